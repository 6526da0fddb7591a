"""The TensorBoard writer: metrics records written as scalars and read back with TensorBoard's own
EventAccumulator; records that are not metrics records, and a missing tensorboard package, fail in one line."""
import importlib.util
import sys

import pytest

from dcslam.depth.tensorboard import TensorBoardWriter, scalars
from dcslam.errors import DcslamError

needs_tensorboard = pytest.mark.skipif(importlib.util.find_spec("tensorboard") is None,
                                       reason="tensorboard not installed (pip install 'dcslam[tensorboard]')")

RECORDS = [
    {"kind": "train", "epoch": 0, "step": 0, "drive": "drive_a", "loss": 2.5, "lr": 1e-3, "pose": 0.25},
    {"kind": "train", "epoch": 0, "step": 1, "drive": "drive_b", "loss": 1.5, "lr": 1e-3, "pose": float("nan")},
    {"kind": "val", "epoch": 0, "step": 2, "mae_mm": 812.0, "rmse_mm": 1400.5, "improved": True},
    {"kind": "train", "epoch": 1, "step": 2, "drive": "drive_a", "loss": 0.75, "lr": 5e-4, "pose": 0.125},
]


@needs_tensorboard
def test_records_read_back_as_scalars(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    with TensorBoardWriter(tmp_path / "tb") as writer:
        for record in RECORDS:
            writer.write(record)
    events = EventAccumulator(str(tmp_path / "tb"))
    events.Reload()
    tags = set(events.Tags()["scalars"])
    assert tags == {"train/loss", "train/lr", "train/pose", "train/epoch", "val/mae_mm", "val/rmse_mm", "val/epoch"}

    def series(tag):
        return [(e.step, e.value) for e in events.Scalars(tag)]

    assert series("train/loss") == [(0, 2.5), (1, 1.5), (2, 0.75)]
    assert series("train/pose") == [(0, 0.25), (2, 0.125)]  # a NaN part is not plotted
    assert series("val/mae_mm") == [(2, 812.0)] and series("val/epoch") == [(2, 0.0)]
    assert series("train/lr") == [(0, pytest.approx(1e-3)), (1, pytest.approx(1e-3)), (2, pytest.approx(5e-4))]


@pytest.mark.parametrize("record", [{"epoch": 0, "step": 1, "loss": 1.0}, {"kind": "train", "loss": 1.0},
                                    {"kind": "train", "step": 1.5}, {"kind": "train", "step": True}, ["kind"]])
def test_a_record_that_is_not_a_metrics_record_fails_in_one_line(record):
    with pytest.raises(DcslamError, match="not a metrics record") as error:
        scalars(record)
    assert "\n" not in str(error.value)


def test_without_tensorboard_the_writer_names_the_extra(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "torch.utils.tensorboard", None)
    with pytest.raises(DcslamError, match=r"pip install 'dcslam\[tensorboard\]'"):
        TensorBoardWriter(tmp_path / "tb")
    assert not (tmp_path / "tb").exists()
