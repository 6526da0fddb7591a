"""Pure metrics: depth errors (KITTI devkit), trajectory errors (thesis localisation accuracy, evo ATE / RPE, KITTI
drift), map chamfer distance, depth PSNR. Workspace-aware scoring and the thesis's tables are :mod:`dcslam.report`."""
