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
from camera_cal.undistort import CalibrationMismatch, Undistorter, build_undistorter, fits

__all__ = [
    "Calibration",
    "CalibrationError",
    "CalibrationMismatch",
    "Undistorter",
    "build_undistorter",
    "calibrate",
    "default_calibration_path",
    "find_board_corners",
    "fits",
    "load_calibration",
    "save_calibration",
]
