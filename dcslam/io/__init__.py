"""File formats: KITTI folders (kitti.py), dcslam drive and layer files (drive.py), TUM trajectories (tum.py)."""
