"""Scores: depth errors (KITTI devkit), trajectory errors (thesis localisation accuracy, evo ATE / RPE), map
chamfer distance, and the thesis's Tables 5.1 / 5.2 assembled from a workspace."""
