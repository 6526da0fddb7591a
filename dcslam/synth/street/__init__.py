"""The street generator: the car's path and motion (trajectory.py), the street scene (scene.py), the camera and
LiDAR (sensors.py), and the KITTI files of each drive (generate.py)."""
