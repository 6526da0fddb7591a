"""Synthetic KITTI: procedural street scenes seen by KITTI's camera 2, Velodyne HDL-64E and OXTS, written in the
KITTI raw + depth-completion layout (``dcslam synth``)."""
from dcslam.synth.generate import DriveReport, DriveTruth, drive_name, generate, make_drive

__all__ = ["DriveReport", "DriveTruth", "drive_name", "generate", "make_drive"]
