"""Geometry: differentiable PyTorch SE(3) (se3.py), pinhole camera back-projection and projection (camera.py) and
normals from vertex maps (normals.py), every function in float32 and float64 on any device; NumPy rotation helpers
(rotations.py: roll-pitch-yaw, quaternions, slerp) and exact nearest neighbours (nearest.py) for files and scores."""
