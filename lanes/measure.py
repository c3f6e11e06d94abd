"""Radius of curvature and the vehicle's offset from the lane centre, in metres."""

from __future__ import annotations

import math

import numpy as np

from lanes.perspective import BirdsEye
from lanes.search import Fit, evaluate_fit


def radius_of_curvature(
    fit: Fit, y_px: float, xm_per_px: float, ym_per_px: float, cap_m: float
) -> float:
    """Radius in metres of x(y) at row y_px (fit rescaled to metres); capped for straights."""
    a = fit[0] * xm_per_px / ym_per_px**2
    b = fit[1] * xm_per_px / ym_per_px
    y = y_px * ym_per_px
    curvature = abs(2 * a) / (1 + (2 * a * y + b) ** 2) ** 1.5
    return float(min(cap_m, 1.0 / curvature)) if curvature > 0 else cap_m


def reported_radius(curvature: float, straight_m: float) -> float:
    """The radius in metres of a bend of `curvature` (1/m), or inf (straight) at `straight_m`
    or past it: a bend that gentle cannot be told from a straight road."""
    return 1.0 / curvature if curvature * straight_m > 1.0 else math.inf


def camera_from(
    fit: Fit,
    bottom_px: float,
    camera: tuple[float, float],
    slant: float,
    xm_per_px: float,
    ym_per_px: float,
) -> float:
    """Metres the camera's ground point `camera` (bird's-eye x, y) lies right of the line
    `fit`, across the road: the line carried on from row `bottom_px` (the view's nearest) down
    to the camera along the road, which slants by `slant` columns a row in the view (a camera
    turned off the road's direction by less than its view is placed for: 1.5 degrees put the
    camera 0.13 m off where read straight down from the bottom row, 4 m ahead of it)."""
    x = float(evaluate_fit(fit, bottom_px))
    across = camera[0] - (x + slant * (camera[1] - bottom_px))
    return across * xm_per_px / math.hypot(1.0, slant * xm_per_px / ym_per_px)


def lane_widths(left: Fit, right: Fit, rows: np.ndarray) -> np.ndarray:
    """Right minus left x at the given rows, in bird's-eye pixels."""
    return evaluate_fit(right, rows) - evaluate_fit(left, rows)


def implausible_lane(
    left: Fit,
    right: Fit,
    rows: np.ndarray,
    xm_per_px: float,
    ym_per_px: float,
    width_m: tuple[float, float],
    max_width_change_m: float,
    min_radius_m: float,
    max_heading_deg: float = 90.0,
) -> str | None:
    """Why a pair of boundaries is not a lane a road can have, or None when it is: its width in
    metres under `width_m` at any of `rows` but the first (the farthest, whose width a horizon a
    few rows off narrows most) or over it at any, the two not near parallel (widths differing by
    more than `max_width_change_m`), either bending tighter than `min_radius_m`, or the lane
    running off more than `max_heading_deg` from straight ahead at the last of `rows` (the
    car's): a car drives along its lane, and lines it crosses at a junction are no lane of its."""
    widths = lane_widths(left, right, rows) * xm_per_px
    if widths[1:].min() < width_m[0] or widths.max() > width_m[1]:
        return f"width {widths.min():.2f}-{widths.max():.2f} m"
    if np.ptp(widths) > max_width_change_m:
        return f"not parallel ({widths.min():.2f}-{widths.max():.2f} m wide)"
    radius = min(
        radius_of_curvature(fit, float(y), xm_per_px, ym_per_px, math.inf)
        for fit in (left, right)
        for y in rows
    )
    if radius < min_radius_m:
        return f"bends at a {radius:.0f} m radius"
    y = float(rows[-1])
    slope = np.mean([2 * fit[0] * y + fit[1] for fit in (left, right)]) * xm_per_px / ym_per_px
    heading = math.degrees(math.atan(abs(float(slope))))
    if heading > max_heading_deg:
        return f"runs {heading:.0f} degrees off straight ahead"
    return None


def lane_figures(
    left: Fit, right: Fit, view: BirdsEye, slant: float, straight_m: float
) -> tuple[float, float, float]:
    """The radius of curvature, the camera's offset from the centre (positive right of it) and
    the width of the lane between `left` and `right` (fits in `view`), in metres, read at the
    view's bottom row: the radius from the mean of the lines' curvatures (not radii, so one
    near-straight line does not dominate; inf at `straight_m` or past it), the offset where
    the camera is, below that row along a road slanting by `slant` (see `camera_from`)."""
    bh = float(view.size[1])
    radii = [
        radius_of_curvature(f, bh, view.xm_per_px, view.ym_per_px, straight_m)
        for f in (left, right)
    ]
    radius = reported_radius(float(np.mean([1.0 / r for r in radii])), straight_m)
    offset = camera_from(
        (left + right) / 2, bh, view.camera_point, slant, view.xm_per_px, view.ym_per_px
    )
    width = float(lane_widths(left, right, np.array([bh]))[0] * view.xm_per_px)
    return radius, offset, width


def carried_fit(fit: Fit, view: BirdsEye, other: BirdsEye, points: int = 24) -> Fit:
    """A line fitted in `view` refitted in `other`, a warp of the same frames: its points over
    the view's rows taken through the frame into the other view. Two warps placed at horizons
    a few rows apart read a lane's width, offset and bend differently (at 360 rows, 1 %
    of the height moved the width by 5 %): the figures are read in the warp measured right."""
    rows = np.linspace(0.0, float(view.size[1]), points)
    frame = view.to_frame(np.stack([evaluate_fit(fit, rows), rows], axis=1))
    moved = other.to_birdseye(frame)
    return np.asarray(np.polyfit(moved[:, 1], moved[:, 0], 2), np.float64)
