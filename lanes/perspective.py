"""Bird's-eye warp of the road ahead, derived from the frame size, and its inverse."""

from __future__ import annotations

import functools
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
    horizon_y: float  # where the trapezoid's sides meet
    live: tuple[int, int, int, int]  # the live box the trapezoid was placed in
    scale_height: float  # the 16:9 height the tuned trapezoid was sized for
    vanishing_x: float | None = None  # the column the sides meet in (None: the live centre's)
    ground_scale: float = 1.0  # a lane's width in pixels at a row, over the tuned camera's

    def warp(self, image: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """The bird's-eye view of a frame."""
        return np.asarray(
            cv2.warpPerspective(image, self.matrix, self.size, flags=cv2.INTER_LINEAR)
        )

    def columns_for(self, width_m: float) -> int:
        """How many bird's-eye columns span `width_m` across the road (at least 1)."""
        return max(1, round(width_m / self.xm_per_px))

    def pixels_for(self, area_m2: float) -> int:
        """How many bird's-eye pixels cover `area_m2` of road (at least 1)."""
        return max(1, round(area_m2 / (self.xm_per_px * self.ym_per_px)))

    @functools.cached_property
    def outside(self) -> NDArray[np.bool_]:
        """The bird's-eye pixels whose road point lies outside the live picture: black in every
        view (where the trapezoid reaches past the picture's side, as it does when sheared to an
        off-centre vanishing point), a still edge for whatever reads the view's motion."""
        bw, bh = self.size
        ys, xs = np.mgrid[0:bh, 0:bw]
        points = self.to_frame(np.column_stack([xs.ravel(), ys.ravel()]) + 0.5)
        lx0, ly0, lx1, ly1 = self.live
        inside = (
            (points[:, 0] >= lx0)
            & (points[:, 0] <= lx1)
            & (points[:, 1] >= ly0)
            & (points[:, 1] <= ly1)
        )
        return np.asarray(~inside.reshape(bh, bw))

    @property
    def camera_column(self) -> float:
        """The frame column of the road line under the camera: the vanishing point's, where
        the view is placed by one, else the live picture's middle. That line runs along the
        road, so it meets the others at the vanishing point, and a level camera sees it upright
        (its vertical vanishing point lies far below the picture: the line leans by a few per
        cent of its distance from the picture's middle). A camera turned 3 degrees sideways
        (or a picture cut off-centre) read its lane offset 0.3 m off with the middle."""
        lx0, _, lx1, _ = self.live
        return (lx0 + lx1) / 2 if self.vanishing_x is None else self.vanishing_x

    @functools.cached_property
    def camera_point(self) -> tuple[float, float]:
        """The camera's ground point (the road under it) in the bird's-eye view, below its
        bottom row: where every upright line of the picture meets once warped (a level camera's
        vertical vanishing point, taken at infinity). Its column is `camera_column`'s."""
        x, y, z = self.matrix @ np.array([0.0, 1.0, 0.0])
        return float(x / z), float(y / z)

    def ray_slope(self, column: float) -> float:
        """The t of the view's `column`: the sideways pixels per row below the horizon of the
        ray from the view's vanishing point that the column shows (every column shows one)."""
        (x0, y0), (x1, y1) = self.to_frame(np.array([[column, 0.0], [column, self.size[1]]]))
        return float((x1 - x0) / (y1 - y0))

    def slant_to(self, column: float) -> float:
        """Columns a row by which road lines running to the vanishing point at frame `column`
        on the view's horizon slant in the view: 0 at the view's own (placed) column."""
        dx, dy, _ = self.matrix @ np.array([column, self.horizon_y, 1.0])
        return float(dx / dy)

    def covered(self, boxes: NDArray[np.floating]) -> NDArray[np.bool_] | None:
        """The bird's-eye pixels under any of the frame's `boxes` (n, 4: x0, y0, x1, y1), their
        parts below the horizon (above it the ground plane has no points); None without."""
        if len(boxes) == 0:
            return None
        bw, bh = self.size
        mask = np.zeros((bh, bw), np.uint8)
        top = self.horizon_y + 0.02 * self.frame_size[1]
        for x0, y0, x1, y1 in np.asarray(boxes, np.float64):
            if y1 <= top:
                continue
            y0 = max(y0, top)
            corners = self.to_birdseye(np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]))
            cv2.fillPoly(mask, [np.round(corners).astype(np.int32)], 1)
        return mask.astype(bool)

    def to_frame(self, points: NDArray[np.floating]) -> NDArray[np.float64]:
        """Bird's-eye (x, y) points mapped to the undistorted frame."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 1, 2)
        return np.asarray(cv2.perspectiveTransform(pts, self.inverse)).reshape(-1, 2)

    def to_birdseye(self, points: NDArray[np.floating]) -> NDArray[np.float64]:
        """Frame (x, y) points mapped to the bird's-eye image."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 1, 2)
        return np.asarray(cv2.perspectiveTransform(pts, self.matrix)).reshape(-1, 2)


def _corners(config: LaneConfig, w: float, h: float) -> NDArray[np.float64]:
    """The config's source trapezoid (top left, top right, bottom right, bottom left) for a
    picture `w` x `h`."""
    return np.array(
        [
            [config.src_top_left_x * w, config.src_top_y * h],
            [config.src_top_right_x * w, config.src_top_y * h],
            [config.src_bottom_right_x * w, config.src_bottom_y * h],
            [config.src_bottom_left_x * w, config.src_bottom_y * h],
        ]
    )


def _apex(corners: NDArray[np.float64]) -> NDArray[np.float64]:
    """Where the trapezoid's left and right sides meet: the vanishing point of the lane."""
    (l0, r0, r1, l1) = corners
    a = np.column_stack([l1 - l0, r0 - r1])
    t = np.linalg.solve(a, r0 - l0)[0]
    return np.asarray(l0 + t * (l1 - l0), np.float64)


def birdseye_for(
    frame_size: tuple[int, int],
    config: LaneConfig,
    horizon_y: float | None = None,
    live: tuple[int, int, int, int] | None = None,
    scale_height: float | None = None,
    vanishing_x: float | None = None,
    ground_scale: float = 1.0,
) -> BirdsEye:
    """The warp for frames of `frame_size`: the config's trapezoid, moved to the scene.

    The trapezoid is the config's (tuned on a 16:9 picture) scaled about its vanishing point so
    that the vanishing point sits on `horizon_y`, centred in the live box, and its bottom at the
    config's share of the live height: lane lines through the vanishing point stay on it, and a
    lane's width in pixels grows with the distance below the horizon as it does for any lens.
    With `vanishing_x` (a camera turned sideways, a picture cut off-centre) the trapezoid is
    sheared about its bottom row so that its sides meet in that column: the road's lines, which
    meet there, stay upright in the bird's-eye view while its bottom stays around the car.

    Along the road the scale needs the focal length, which a flat road does not reveal (a lens
    twice as long on a road twice as stretched gives the same picture): `scale_height` is the
    height of the 16:9 picture of the tuned lens at this picture's scale (the live height when
    not given); the tuned trapezoid and the bird's-eye image are sized for it.

    `ground_scale` is how wide a lane is at a row (below the horizon) against the tuned camera:
    a camera twice as high sees it half as wide (0.5), and each row twice as far. The trapezoid
    narrows by it about the vanishing point, so lanes keep their bird's-eye columns, and covers
    that much more road.
    """
    w, h = frame_size
    lx0, ly0, lx1, ly1 = live or (0, 0, w, h)
    lh = ly1 - ly0
    ref_h = float(lh if scale_height is None else scale_height)
    ref_w = ref_h * 16 / 9  # the width the x fractions were tuned for, at this height
    reference = _corners(config, ref_w, ref_h)
    apex = _apex(reference)
    horizon = ly0 + apex[1] * lh / ref_h if horizon_y is None else horizon_y
    bottom = ly0 + config.src_bottom_y * lh
    # (A horizon given near the bottom still leaves a fifth of the tuned trapezoid's height.)
    scale = max((bottom - horizon) / (config.src_bottom_y * ref_h - apex[1]), 0.2)
    centre = (lx0 + lx1) / 2 + apex[0] - ref_w / 2
    src = np.array([centre, horizon]) + scale * (reference - apex) * np.array([ground_scale, 1.0])
    if vanishing_x is not None and bottom > horizon:
        src[:, 0] += (vanishing_x - centre) * (bottom - src[:, 1]) / (bottom - horizon)
    sized = min(ref_h, config.max_warp_frame_height)
    bw, bh = round(sized * 16 / 9 * config.warp_width), round(sized * config.warp_height)
    dst = np.array(
        [
            [config.dst_left_x * bw, 0],
            [config.dst_right_x * bw, 0],
            [config.dst_right_x * bw, bh],
            [config.dst_left_x * bw, bh],
        ],
        dtype=np.float32,
    )
    matrix = np.asarray(cv2.getPerspectiveTransform(src.astype(np.float32), dst), np.float64)
    inverse = np.asarray(cv2.getPerspectiveTransform(dst, src.astype(np.float32)), np.float64)
    lane_px = (config.dst_right_x - config.dst_left_x) * bw
    # A road point at row v is K / (v - horizon) ahead: rows `scale` times further below the
    # horizon are `scale` times nearer, so the trapezoid covers that much less road.
    length = config.warp_length_m / scale / ground_scale
    return BirdsEye(
        frame_size=(w, h),
        size=(bw, bh),
        matrix=matrix,
        inverse=inverse,
        xm_per_px=config.lane_width_m / lane_px,
        ym_per_px=length / bh,
        horizon_y=float(horizon),
        live=(lx0, ly0, lx1, ly1),
        scale_height=ref_h,
        vanishing_x=vanishing_x,
        ground_scale=ground_scale,
    )
