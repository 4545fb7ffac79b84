"""Seeing the table: frame sources, calibration, ball detection, the opponent's rods.

Needs OpenCV (``pip install -e ".[hardware]"``); never the simulator.
"""

from foosball_gym.real_table.vision.calibration import (
    FIELD_MARKERS,
    calibrate_extrinsics,
    calibrate_from_frame,
    calibrate_intrinsics,
    find_field_corners,
)
from foosball_gym.real_table.vision.detectors import (
    BallDetector,
    ColourBallDetector,
    Detection,
    OnnxBallDetector,
    decode_yolo,
)
from foosball_gym.real_table.vision.projection import CameraCalibration
from foosball_gym.real_table.vision.rods import RodTracker, fit_slide
from foosball_gym.real_table.vision.sources import CallableSource, FrameSource, OpenCVSource

__all__ = [
    "FIELD_MARKERS",
    "BallDetector",
    "CallableSource",
    "CameraCalibration",
    "ColourBallDetector",
    "Detection",
    "FrameSource",
    "OnnxBallDetector",
    "OpenCVSource",
    "RodTracker",
    "calibrate_extrinsics",
    "calibrate_from_frame",
    "calibrate_intrinsics",
    "decode_yolo",
    "find_field_corners",
    "fit_slide",
]
