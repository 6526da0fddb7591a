"""`dcslam demo-icl`: depth denoising learnt through the map (options: dcslam.stages.demo_icl)."""
from __future__ import annotations

import time

from dcslam.cli.app import app, summary
from dcslam.cli.options import stage_command
from dcslam.stages import demo_icl

HELP = (
    "The thesis's appendix C.2 experiment: a DnCNN learns to remove Gaussian noise from depth images when trained "
    "only with the chamfer distance between the PointFusion map (ground-truth poses) of its output and that of the "
    "clean depth. Prints, for the noisy input and the denoised output on held-out frames, MAE / RMSE (mm) and PSNR "
    "against the clean depth and the chamfer distance of their maps to the clean map.\n\n"
    "Data: --drives (a drive file, or a folder with splits.json from `dcslam prepare-tum`: train and val drives "
    "train, test drives are held out), else indoor rooms generated in the ICL-NUIM layout and prepared under "
    "<workspace>/demo-icl/ (kept for the next run; the last room is held out).\n\n"
    "Writes <workspace>/results/demo-icl/: results.md, results.csv, results.json (settings, scores, frames, "
    "losses), denoising.png (noisy, denoised and clean depth of held-out frames, like the thesis's figure C.6) "
    "and model.pt. About 70 s with the defaults on two quiet CPU cores."
)


def run(ws, config: demo_icl.DemoIclConfig, *, force: bool = False):
    start = time.perf_counter()
    return demo_icl.run(ws, config, force=force), time.perf_counter() - start


def report(result) -> None:
    from dcslam.cli.score import print_table

    denoised, seconds = result
    print_table(denoised.table)
    summary(f"results in {denoised.out_dir} (results.md, results.csv, results.json, denoising.png, model.pt); "
            f"{seconds:.0f} s")


demo_icl_command = stage_command(app, "demo-icl", demo_icl.DemoIclConfig, run, report, help=HELP,
                                 examples=("dcslam demo-icl --force", "dcslam demo-icl --sigma 0.02 --steps 200"))
