"""Depth completion: models (SparseConvNet, IP-Basic, DnCNN), losses (masked MSE, chamfer), training and prediction.

Library code only; ``dcslam train`` and ``dcslam predict`` are thin wrappers over :mod:`dcslam.depth.train` and
:mod:`dcslam.depth.predict`.
"""
