"""Differentiable dense SLAM in PyTorch: point maps (pointmap.py), odometry (odometry.py, solvers.py, robust.py:
Geman-McClure kernel and KISS-ICP's adaptive threshold), mappers (fusion.py: PointFusion; icpslam.py: ICP-SLAM map),
the frame loop (pipeline.py), per-step health verdicts (health.py) and the settings (config.py)."""
