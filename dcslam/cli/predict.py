"""`dcslam predict`: write a prediction layer per drive with a trained run or a classical completer
(options: dcslam.stages.predict)."""
from __future__ import annotations

from dcslam.cli.app import app, summary
from dcslam.cli.options import stage_command
from dcslam.stages import predict

HELP = ("Complete the sparse depth of drives with a trained run (or a classical completer: IP-Basic, scanline, "
        "planefit) and write "
        "predictions/<run>/<drive>.h5 (with --model, predictions/<completer>/, e.g. ip-basic-fast).")


def report(result: predict.PredictResult) -> None:
    empty = "" if result.empty_share is None else f" ({100 * result.empty_share:.1f} % of the pixels left empty)"
    summary(f"{len(result.layers)} prediction layer(s) by {result.made_by} in {result.out_dir}{empty}")


predict_command = stage_command(app, "predict", predict.PredictConfig, predict.run, report, help=HELP,
                                examples=("dcslam predict --run mse-dense",
                                          "dcslam predict --model ip-basic-fast    # no training needed"))
