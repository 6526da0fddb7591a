"""``dcslam synth``: generate KITTI-format drives (or ICL-NUIM-layout indoor sequences) from procedural scenes."""
from __future__ import annotations

import contextlib
from dataclasses import dataclass
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.stages.config import option
from dcslam.workspace import Workspace


MIN_FRAMES = 11  # KITTI gives no depth map to the first and last 5 raw frames of a drive


@dataclass(frozen=True)
class SynthConfig:
    """Options of ``dcslam synth``."""

    out: Path | None = option(None, flags=("--out", "-o"), show_default="<workspace>/kitti, with --indoor "
                              "<workspace>/tum", help="KITTI root to write into (raw/ and depth_completion/); with "
                              "--indoor, the folder of the sequences.")
    drives: int = option(6, flags=("--drives", "-n"), min=1,
                         help="Number of drives (with --indoor: sequences) to generate.")
    frames: int = option(60, flags=("--frames", "-f"), min=1,
                         help="Raw frames per drive (10 Hz). Like KITTI, only frames 5 … N−6 get depth maps, so "
                              "N ≥ 11.")
    seed: int = option(0, flags=("--seed", "-s"),
                       help="Random seed; each drive's scene and path follow from (seed, drive index).")
    azimuth_step: float = option(0.08, flags=("--lidar-azimuth-step",),
                                 help="LiDAR azimuth step in degrees across the 64 beams (each laser fires every "
                                      "second step, as the HDL-64E).")
    indoor: bool = option(False, flags=("--indoor",),
                          help="Write indoor sequences in the ICL-NUIM layout instead of KITTI drives.")
    scale: float = option(1.0, min=0.05, max=4.0, help="With --indoor: image size as a fraction of 640 × 480 "
                                                        "(intrinsics scaled to match).")
    jobs: int = option(1, min=1, help="Street drives written at once, in worker processes (e.g. the number of CPU "
                                      "cores); the files are the same for any value.")

    def __post_init__(self) -> None:
        if self.drives < 1 or self.frames < 1:
            raise DcslamError(f"synth needs at least 1 drive of 1 frame, got {self.drives} of {self.frames}")
        if not self.indoor and self.frames < MIN_FRAMES:
            raise DcslamError(f"--frames {self.frames} gives no frame a depth map (KITTI skips 5 frames at each "
                              f"end); pass --frames {MIN_FRAMES} or more")
        if not 0.05 <= self.scale <= 4.0:
            raise DcslamError(f"--scale must be in [0.05, 4], got {self.scale}")
        if self.jobs < 1:
            raise DcslamError(f"--jobs must be >= 1, got {self.jobs}")
        if not self.azimuth_step > 0:
            raise DcslamError(f"--lidar-azimuth-step must be > 0 degrees, got {self.azimuth_step}")


@dataclass
class SynthResult:
    """What was written: ``root``, the per-drive (or per-sequence) reports, and ``notes`` for the user."""

    root: Path
    indoor: bool
    reports: list
    notes: list[str]


def out_root(ws: Workspace, config: SynthConfig) -> Path:
    if config.out is not None:
        return config.out
    return ws.root / "tum" if config.indoor else ws.kitti


@contextlib.contextmanager
def _no_debris(root: Path):
    """On a failed or interrupted run, remove the calibration files and the still-empty folders this run made under
    the KITTI root ``root`` (the drives are written whole or not at all by the generator), so that no tree is left
    that looks like a dataset."""
    from dcslam.io.kitti_calib import CALIB_FILES
    from dcslam.synth.street.generate import DATE

    date_dir = root / "raw" / DATE
    files = [date_dir / name for name in CALIB_FILES]
    folders = [date_dir, root / "raw", root / "depth_completion" / "train", root / "depth_completion", root]
    before = {path for path in (*files, *folders) if path.exists()}
    try:
        yield
    except BaseException:
        for path in files:
            if path not in before:
                path.unlink(missing_ok=True)
        for folder in folders:
            if folder not in before:
                with contextlib.suppress(OSError):  # not empty: it holds something this run did not make
                    folder.rmdir()
        raise


def run(ws: Workspace, config: SynthConfig, *, force: bool = False) -> SynthResult:
    """Generate the drives (or sequences) of ``config`` under :func:`out_root`."""
    from dcslam.workspace import output_folder

    from dcslam.locks import output_lock

    root = output_folder(out_root(ws, config), "--out")
    with output_lock(root, "synthetic dataset"):  # one writer at a time, before anything is removed or written
        return _generate(root, config, force)


def _generate(root: Path, config: SynthConfig, force: bool) -> SynthResult:
    from dcslam.progress import Bar

    if config.indoor:
        from dcslam.synth.indoor import generate_indoor

        with Bar("synth --indoor", total=config.drives * config.frames) as bar:
            result = generate_indoor(root, sequences=config.drives, frames=config.frames, seed=config.seed,
                                     force=force, on_frame=bar.advance, scale=config.scale)
        return SynthResult(root, True, list(result.sequences), [])
    from dcslam.synth import generate

    notes: list[str] = []
    with Bar("synth", total=config.drives * config.frames) as bar, _no_debris(root):
        reports = generate(root, drives=config.drives, frames=config.frames, seed=config.seed, force=force,
                           lidar_azimuth_step_deg=config.azimuth_step, on_frame=bar.advance, jobs=config.jobs)
    return SynthResult(root, False, reports, notes)
