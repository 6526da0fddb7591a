"""Numbers that several packages must agree on, kept below all of them so that imports run one way."""

MIN_DEPTH_M = 0.1
"""Depths below 0.1 m are holes, not depths: no KITTI sensor measures that near. Predictions are cut there, SLAM
frames ignore nearer pixels, and scoring (:mod:`dcslam.eval.depth`) counts nearer predictions as missing."""

FIRST_STEP_PRIORS = ("none", "drive-motion")
"""What predicts SLAM's first ICP step, which has no velocity yet: nothing, or the drive poses' motion from frame 0
to 1. Here so that the settings (:mod:`dcslam.slam.config`) and the loop (:mod:`dcslam.slam.pipeline`) agree without
importing each other."""
