"""Differentiable geometry in PyTorch: SE(3) (se3.py), pinhole camera back-projection and projection (camera.py),
normals from vertex maps (normals.py). Every function works in float32 and float64 on any device."""
