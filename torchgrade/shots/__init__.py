"""Shots: the frames a look grades in order (files, folders, globs, ``name.%04d.exr`` patterns), where each graded
frame is written and in which file format, and the per-frame function that carries eye adaptation from frame to frame.
``torchgrade grade`` and :mod:`torchgrade.integrations.ray` are both front ends of this package.

* :mod:`~torchgrade.shots.frames`: :func:`shot_frames`, :func:`output_paths`, :func:`render_frame`, :func:`grade_shot`;
* :mod:`~torchgrade.shots.outputs`: :func:`check_output`, :func:`write_frame` (PNG, TIFF, OpenEXR).
"""

from .frames import grade_shot, output_paths, render_frame, shot_frames
from .outputs import BIT_DEPTHS, check_output, write_frame

__all__ = ["shot_frames", "output_paths", "render_frame", "grade_shot", "BIT_DEPTHS", "check_output", "write_frame"]
