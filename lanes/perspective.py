"""Bird's-eye warp of the road ahead, derived from the frame size, and its inverse."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from lanes.config import LaneConfig


@dataclass(frozen=True, eq=False)
class BirdsEye:
    """Perspective maps between the undistorted frame and the bird's-eye image."""

    frame_size: tuple[int, int]  # (width, height)
    size: tuple[int, int]  # bird's-eye (width, height)
    matrix: NDArray[np.float64]
    inverse: NDArray[np.float64]
    xm_per_px: float
    ym_per_px: float

    def warp(self, image: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """The bird's-eye view of a frame."""
        return np.asarray(
            cv2.warpPerspective(image, self.matrix, self.size, flags=cv2.INTER_LINEAR)
        )

    def pixels_for(self, area_m2: float) -> int:
        """How many bird's-eye pixels cover `area_m2` of road (at least 1)."""
        return max(1, round(area_m2 / (self.xm_per_px * self.ym_per_px)))

    def to_frame(self, points: NDArray[np.floating]) -> NDArray[np.float64]:
        """Bird's-eye (x, y) points mapped to the undistorted frame."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 1, 2)
        return np.asarray(cv2.perspectiveTransform(pts, self.inverse)).reshape(-1, 2)

    def to_birdseye(self, points: NDArray[np.floating]) -> NDArray[np.float64]:
        """Frame (x, y) points mapped to the bird's-eye image."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 1, 2)
        return np.asarray(cv2.perspectiveTransform(pts, self.matrix)).reshape(-1, 2)


def birdseye_for(frame_size: tuple[int, int], config: LaneConfig) -> BirdsEye:
    """The warp for frames of `frame_size`, from the fractions in `config`."""
    w, h = frame_size
    bw, bh = round(w * config.warp_width), round(h * config.warp_height)
    src = np.array(
        [
            [config.src_top_left_x * w, config.src_top_y * h],
            [config.src_top_right_x * w, config.src_top_y * h],
            [config.src_bottom_right_x * w, config.src_bottom_y * h],
            [config.src_bottom_left_x * w, config.src_bottom_y * h],
        ],
        dtype=np.float32,
    )
    dst = np.array(
        [
            [config.dst_left_x * bw, 0],
            [config.dst_right_x * bw, 0],
            [config.dst_right_x * bw, bh],
            [config.dst_left_x * bw, bh],
        ],
        dtype=np.float32,
    )
    matrix = np.asarray(cv2.getPerspectiveTransform(src, dst), dtype=np.float64)
    inverse = np.asarray(cv2.getPerspectiveTransform(dst, src), dtype=np.float64)
    lane_px = (config.dst_right_x - config.dst_left_x) * bw
    return BirdsEye(
        frame_size=(w, h),
        size=(bw, bh),
        matrix=matrix,
        inverse=inverse,
        xm_per_px=config.lane_width_m / lane_px,
        ym_per_px=config.warp_length_m / bh,
    )
