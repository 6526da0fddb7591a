"""Differentiable dense SLAM in PyTorch: point maps (pointmap.py), odometry (odometry.py, solvers.py),
mappers (fusion.py: PointFusion; icpslam.py: ICP-SLAM map), and the frame loop (pipeline.py)."""
