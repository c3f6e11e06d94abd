"""Camera calibration from chessboard photos, per-frame undistortion, and the scene geometry
(live picture and horizon), the camera's roll and the picture's way up read off the footage."""

from camera_cal.calibration import (
    Calibration,
    CalibrationError,
    calibrate,
    calibrate_frames,
    default_calibration_path,
    find_board_corners,
    load_calibration,
    save_calibration,
    turned,
)
from camera_cal.level import LevelConfig, RollReading
from camera_cal.scene import (
    US_DASH_SPACING_M,
    DashScale,
    GroundScale,
    SceneGeometry,
    SceneTracker,
    horizon_estimates,
    monochrome,
)
from camera_cal.shots import ShotDetector, same_camera
from camera_cal.undistort import (
    CalibrationMismatch,
    Undistorter,
    build_undistorter,
    calibrated_scale_height,
    fits,
    focal_scale_height,
    undistorter_for,
)
from camera_cal.upright import (
    SIDES,
    SkyVote,
    UprightConfig,
    frame_sky,
    frames_vote,
    sky_scores,
    sky_side,
    sky_vote,
)

__all__ = [
    "SIDES",
    "US_DASH_SPACING_M",
    "Calibration",
    "CalibrationError",
    "CalibrationMismatch",
    "DashScale",
    "GroundScale",
    "LevelConfig",
    "RollReading",
    "SceneGeometry",
    "SceneTracker",
    "ShotDetector",
    "SkyVote",
    "Undistorter",
    "UprightConfig",
    "build_undistorter",
    "calibrate",
    "calibrate_frames",
    "calibrated_scale_height",
    "default_calibration_path",
    "find_board_corners",
    "fits",
    "focal_scale_height",
    "frame_sky",
    "frames_vote",
    "horizon_estimates",
    "load_calibration",
    "monochrome",
    "same_camera",
    "save_calibration",
    "sky_scores",
    "sky_side",
    "sky_vote",
    "turned",
    "undistorter_for",
]
