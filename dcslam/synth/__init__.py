"""Synthetic data in real file layouts, for machines that cannot download datasets.

- ``street/``: procedural street scenes seen by KITTI's camera 2, Velodyne HDL-64E and OXTS, written in the KITTI
  raw + depth-completion layout (``dcslam synth``);
- ``indoor/``: furnished rooms seen by a hand-held camera, written in the ICL-NUIM layout (``dcslam synth --indoor``);
- shared by both: the solids (``shapes.py``), the ground (``terrain.py``), texture noise (``noise.py``) and the ray
  caster (``raycast.py``). Every file format is written through :mod:`dcslam.io`.
"""
from dcslam.synth.street.generate import DriveReport, DriveTruth, drive_name, generate, make_drive

__all__ = ["DriveReport", "DriveTruth", "drive_name", "generate", "make_drive"]
