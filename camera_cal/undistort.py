"""Undistortion with remap maps precomputed once per frame size."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from camera_cal.calibration import (
    Calibration,
    CalibrationError,
    default_calibration_path,
    load_calibration,
)

ASPECT_TOLERANCE = 0.01
# The undistorted picture keeps the lens's focal length, so its distances keep the lens's scale;
# a barrel lens's sides then stretch out of the frame. The shipped lens still shows 92 % of its
# picture's width (along the principal point's row); a wider one would show much less (one of
# focal length half the width, 78 %: the next lanes' cars cut off), so its view is zoomed out
# just enough to show this share.
MIN_KEPT_WIDTH = 0.9
STRIPE_ROWS = 32  # rows remapped per call (see Undistorter.__call__)


@dataclass(frozen=True, eq=False)
class Undistorter:
    """Maps a distorted frame of one size to the undistorted frame (same size, same matrix)."""

    size: tuple[int, int]  # (width, height)
    camera_matrix: NDArray[np.float64]
    map1: NDArray[np.int16]
    map2: NDArray[np.uint16]

    def __call__(self, frame: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """Undistort one frame; its size must be the one this undistorter was built for."""
        height, width = frame.shape[:2]
        if (width, height) != self.size:
            raise CalibrationMismatch((width, height), self.size)
        out = np.empty_like(frame)
        # In stripes of rows: the same pixels, but each stripe's source rows stay in the cache
        # (at 1080p 13.5 -> 6-7 ms a frame on one core; one call over the whole frame is slower).
        for top in range(0, height, STRIPE_ROWS):
            rows = slice(top, top + STRIPE_ROWS)
            cv2.remap(frame, self.map1[rows], self.map2[rows], cv2.INTER_LINEAR, dst=out[rows])
        return out


class CalibrationMismatch(CalibrationError):  # noqa: N818 (a kind of CalibrationError)
    """Frames of a size whose aspect ratio differs from the calibration's: another camera."""

    def __init__(self, frame_size: tuple[int, int], calibration_size: tuple[int, int]) -> None:
        (fw, fh), (cw, ch) = frame_size, calibration_size
        super().__init__(
            f"frame is {fw}x{fh} but the calibration is for {cw}x{ch}, another aspect ratio"
        )
        self.frame_size = frame_size
        self.calibration_size = calibration_size


def fits(calibration: Calibration, size: tuple[int, int]) -> bool:
    """Whether frames of `size` (width, height) have the calibration's aspect ratio."""
    width, height = size
    cal_width, cal_height = calibration.image_size
    return abs(width / height - cal_width / cal_height) <= ASPECT_TOLERANCE * cal_width / cal_height


def scaled_camera_matrix(calibration: Calibration, size: tuple[int, int]) -> NDArray[np.float64]:
    """The camera matrix for frames of another size with the same aspect ratio (same camera)."""
    width, height = size
    cal_width, cal_height = calibration.image_size
    if (width, height) == (cal_width, cal_height):
        return calibration.camera_matrix.copy()
    if not fits(calibration, size):
        raise CalibrationMismatch(size, calibration.image_size)
    sx, sy = width / cal_width, height / cal_height
    matrix = calibration.camera_matrix.copy()
    # Pixel centres move with the half-pixel convention: x' = (x + 0.5) * s - 0.5.
    matrix[0, 0] *= sx
    matrix[1, 1] *= sy
    matrix[0, 2] = (matrix[0, 2] + 0.5) * sx - 0.5
    matrix[1, 2] = (matrix[1, 2] + 0.5) * sy - 0.5
    return matrix


def kept_width(
    calibration: Calibration, size: tuple[int, int], matrix: NDArray[np.float64]
) -> float:
    """The share of the picture's width, along the principal point's row, that the undistorted
    view through `matrix` shows (for frames of `size`; the rest falls outside its frame)."""
    lens = scaled_camera_matrix(calibration, size)
    row = matrix[1, 2]
    ends = np.array([[0.0, row], [size[0] - 1.0, row]])
    rays = np.column_stack([(ends - matrix[:2, 2]) / np.diag(matrix)[:2], np.ones(2)])
    seen, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), lens, calibration.dist_coeffs)
    left, right = np.clip(seen.reshape(2, 2)[:, 0], 0.0, size[0] - 1.0)
    return float((right - left) / (size[0] - 1.0))


def output_camera_matrix(calibration: Calibration, size: tuple[int, int]) -> NDArray[np.float64]:
    """The camera matrix of the undistorted frames of `size`: the lens's own, or, for a lens
    whose undistorted view would show less than MIN_KEPT_WIDTH of the picture's width, with its
    focal length shortened (about the same principal point) until it shows that share."""
    matrix = scaled_camera_matrix(calibration, size)
    if kept_width(calibration, size, matrix) >= MIN_KEPT_WIDTH:
        return matrix

    def zoomed(factor: float) -> NDArray[np.float64]:
        out = matrix.copy()
        out[0, 0] *= factor
        out[1, 1] *= factor
        return out

    low, high = 0.05, 1.0  # shortest focal length tried; the lens's own
    for _ in range(40):  # the longest focal length that shows the share
        middle = (low + high) / 2
        low, high = (
            (middle, high)
            if kept_width(calibration, size, zoomed(middle)) >= MIN_KEPT_WIDTH
            else (low, middle)
        )
    return zoomed(low)


def build_undistorter(
    calibration: Calibration | None, size: tuple[int, int], roll_deg: float = 0.0
) -> Undistorter:
    """Precompute fixed-point remap maps for frames of `size` (width, height): undistorted by
    `calibration` (None: a lens without distortion) and levelled, for a camera mounted turned
    about its axis so that the picture is turned `roll_deg` degrees anticlockwise (its horizon
    rising to the right), by turning it back about the principal point (no cost per frame)."""
    if calibration is None:  # turned about the centre (the focal length plays no part)
        cx, cy = (size[0] - 1) / 2, (size[1] - 1) / 2
        lens = np.array([[size[1], 0.0, cx], [0.0, size[1], cy], [0.0, 0.0, 1.0]])
        matrix, distortion = lens, np.zeros(5)
    else:
        lens = scaled_camera_matrix(calibration, size)
        matrix, distortion = output_camera_matrix(calibration, size), calibration.dist_coeffs
    map1, map2 = cv2.initUndistortRectifyMap(
        lens, distortion, level_rotation(roll_deg), matrix, size, cv2.CV_16SC2
    )
    return Undistorter(size=size, camera_matrix=matrix, map1=map1, map2=map2)


def undistorter_for(
    calibration: Calibration | None, size: tuple[int, int], roll_deg: float = 0.0
) -> Undistorter | None:
    """`build_undistorter`'s for frames of `size`, or None when there is neither a lens to undo
    nor a turn to level: the frames are used as they are."""
    if calibration is None and not roll_deg:
        return None
    return build_undistorter(calibration, size, roll_deg)


def level_rotation(roll_deg: float) -> NDArray[np.float64] | None:
    """The rotation about the optical axis that turns a picture turned `roll_deg` degrees
    anticlockwise back to level (x right, y down: a positive angle turns it clockwise on the
    screen); None for none."""
    if roll_deg == 0:
        return None
    a = np.radians(roll_deg)
    return np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])


def calibrated_scale_height(calibration: Calibration, size: tuple[int, int]) -> float:
    """The scale height (see `camera_cal.scene.scale_height`) of frames of `size` from a
    calibrated camera: the undistorted frames' focal length in units of the shipped camera's,
    whose 16:9 picture the stages were tuned on, so distances follow the lens instead of an
    assumed one."""
    shipped = load_calibration(default_calibration_path())
    fy = output_camera_matrix(calibration, size)[1, 1]
    return float(fy / shipped.camera_matrix[1, 1] * shipped.image_size[1])


# The width of a 4:3 picture whose diagonal is a 35 mm film frame's (36 x 24 mm: 43.27 mm), in
# mm: a 35 mm-equivalent focal length is a phone's over its 4:3 sensor, whose full width its
# 16:9 video keeps (an iPhone 13 mini's 26 mm main camera: 67.8 degrees across, as it reports).
EQUIVALENT_WIDTH_MM = 0.8 * float(np.hypot(36.0, 24.0))


def focal_length_px(focal_mm: float, size: tuple[int, int]) -> float:
    """The focal length in pixels of frames of `size` from a lens of `focal_mm` in 35 mm terms,
    spanning the picture's longer side as the sensor's width (a phone held upright turns it)."""
    return focal_mm / EQUIVALENT_WIDTH_MM * max(size)


def equivalent_focal_mm(focal_px: float, size: tuple[int, int]) -> float:
    """The 35 mm-equivalent focal length of a lens of `focal_px` pixels on frames of `size` (the
    inverse of `focal_length_px`)."""
    return focal_px * EQUIVALENT_WIDTH_MM / max(size)


def focal_scale_height(focal_mm: float, size: tuple[int, int]) -> float:
    """The scale height (see `calibrated_scale_height`) of frames of `size` from a camera without
    a calibration whose lens's 35 mm-equivalent focal length is known (a phone tags its videos
    with it): a lens without distortion of that focal length."""
    shipped = load_calibration(default_calibration_path())
    focal = focal_length_px(focal_mm, size)
    return float(focal / shipped.camera_matrix[1, 1] * shipped.image_size[1])
