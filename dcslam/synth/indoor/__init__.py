"""Synthetic indoor sequences in the ICL-NUIM TUM-compatible layout (``dcslam synth --indoor``): the room
(room.py), the camera and its hand-held path (camera.py), rendering (render.py) and the files (generate.py).

The room: walls, floor and ceiling (a flat :class:`~dcslam.synth.terrain.Terrain` as the floor, slabs for the
rest), furniture along the walls (bookshelves with rows of books, sideboards with doors and things on top, sofas
with cushions, tables with chairs, plants), pictures, a door and a window on the walls, a rug and a low table in
the middle, lit by a ceiling lamp. Shapes are the street generator's primitives (:class:`~dcslam.synth.shapes.Shape`)
and are ray cast by :func:`dcslam.synth.raycast.cast`, so depth is exact and colour edges fall on depth edges.

The camera is ICL-NUIM's: ``fy < 0``, its y axis points *up* (see :mod:`dcslam.io.tum_rgbd`). Its poses are proper
rotations in this generator's z-up world, so the images show the room mirrored left to right, exactly as ICL-NUIM's
images relate to its poses; back-projecting with the negative fy puts every pixel back where it was. The hand-held
trajectory is smooth: the camera wanders over the middle of the room at 1.1-1.6 m height (at most 3 cm per frame,
sums of slow sinusoids plus a millimetre of hand shake) while turning slowly (at most about 1 degree per frame),
looking a little down. Depth is noise-free (ICL-NUIM's ``living_room_traj<i>_frei_png``, not its noisy ``n``
variant); colour has a little sensor noise.
"""
from dcslam.synth.indoor.camera import camera_K, handheld_trajectory
from dcslam.synth.indoor.generate import (IndoorResult, IndoorSequence, generate_indoor, sequence_name, trajectory_name,
                                          write_sequence)
from dcslam.synth.indoor.render import Look, render
from dcslam.synth.indoor.room import CEILING, WALL, Room, build_room

__all__ = ["CEILING", "WALL", "IndoorResult", "IndoorSequence", "Look", "Room", "build_room", "camera_K",
           "generate_indoor", "handheld_trajectory", "render", "sequence_name", "trajectory_name", "write_sequence"]
