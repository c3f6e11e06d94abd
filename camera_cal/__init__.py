"""Camera calibration from chessboard photos and per-frame undistortion."""

from camera_cal.calibration import (
    Calibration,
    CalibrationError,
    calibrate,
    default_calibration_path,
    find_board_corners,
    load_calibration,
    save_calibration,
)
from camera_cal.undistort import Undistorter, build_undistorter

__all__ = [
    "Calibration",
    "CalibrationError",
    "Undistorter",
    "build_undistorter",
    "calibrate",
    "default_calibration_path",
    "find_board_corners",
    "load_calibration",
    "save_calibration",
]
