"""``dcslam slam``: dense SLAM over drive files, writing per drive a TUM trajectory, a PLY map and a JSON summary
(with the configuration that ran) under ``slam/<layer>/``.

The configuration extends :class:`dcslam.slam.config.SlamSettings`, so a field added there is an option of
``dcslam slam`` and a configuration-file key with no other edit.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.slam.config import SlamSettings
from dcslam.stages.config import option
from dcslam.workspace import Workspace


@dataclass(frozen=True)
class SlamStageConfig(SlamSettings):
    """Options of ``dcslam slam``: the SLAM's settings plus its input, frames, output and device."""

    depth: str = option("dense", help="Depth input: sparse, dense, predicted (a `dcslam predict` layer), filtered "
                                      "(a `dcslam filter` layer), predicted/<run>, filtered/<name>, or a layer "
                                      "folder or file path.")
    drive: list[str] = option(default_factory=list, help="Drive name (in drives/) or .h5 path; repeatable. "
                                                          "Default: the test drives of splits.json.")
    frames: int = option(0, min=0, help="First N frames of each drive (0 = all; the thesis scored 30).")
    run: str | None = option(None, help="Prediction run (or filter name) for --depth predicted (filtered); "
                                        "default: the most recent.")
    out: Path | None = option(None, help="Output folder (default: slam/<layer>/).")
    device: str = option("cpu", help="torch device, e.g. cpu or cuda.")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.frames < 0:
            raise DcslamError(f"--frames must be >= 0, got {self.frames}")

    def settings(self) -> SlamSettings:
        """The SLAM algorithm's own settings (what :func:`dcslam.slam.config.build_slam` takes)."""
        return SlamSettings(**{f.name: getattr(self, f.name) for f in fields(SlamSettings)})


@dataclass
class SlamDriveResult:
    """One drive: its summary (:meth:`dcslam.slam.run.DriveRun.summary`) and the files written."""

    drive: str
    summary: dict
    written: dict[str, Path]


def run(ws: Workspace, config: SlamStageConfig, *, force: bool = False) -> list[SlamDriveResult]:
    """SLAM over every selected drive; all outputs are checked not to exist (without ``force``) before any work."""
    from dcslam.io.drive import read_splits
    from dcslam.slam.config import build_slam
    from dcslam.slam.run import check_outputs, run_drive, write_outputs
    from dcslam.stages.config import to_dict
    from dcslam.workspace import drive_file, layer_reference, resolve_layer

    names = config.drive or read_splits(ws.splits)["test"]
    paths = [drive_file(ws, name) for name in names]
    layer = resolve_layer(ws, layer_reference(config.depth, config.run))
    out_dir = config.out if config.out is not None else ws.slam / layer.name
    jobs = []
    for path in paths:
        source = layer.require(path.stem)
        check_outputs(out_dir, path.stem, force)
        jobs.append((path, source))
    results = []
    for path, source in jobs:
        slam = build_slam(config.settings())
        drive_run = run_drive(path, source, slam, config.frames or None, config.device,
                              settings={**to_dict(config), "source": str(source)})
        drive_run.name = path.stem
        written = write_outputs(drive_run, out_dir, force)
        results.append(SlamDriveResult(path.stem, drive_run.summary(), written))
    return results
