"""Finding each line's pixels in the bird's-eye mask: sliding windows or a margin around a prior."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

Fit = NDArray[np.float64]  # x = a y^2 + b y + c in bird's-eye pixels


@dataclass(frozen=True, eq=False)
class LinePixels:
    """Pixels attributed to one line, and the search windows used (x1, y1, x2, y2)."""

    x: NDArray[np.float64]
    y: NDArray[np.float64]
    windows: tuple[tuple[int, int, int, int], ...] = ()

    def __len__(self) -> int:
        return len(self.x)


@dataclass(frozen=True, eq=False)
class Paint:
    """A bird's-eye mask and its paint pixels, found once per frame for both lines' searches."""

    mask: NDArray[np.uint8]
    ys: NDArray[np.intp]
    xs: NDArray[np.intp]

    @classmethod
    def of(cls, mask: NDArray[np.uint8]) -> Paint:
        """The paint pixels of `mask`."""
        ys, xs = np.nonzero(mask)
        return cls(mask, ys, xs)


def fit_line(pixels: LinePixels, max_bend: float = np.inf) -> Fit | None:
    """Second-order fit x(y); near rows weigh more since they are sharper. Its y^2 term is at
    most `max_bend` in size (beyond it, refitted with the term at that bound: the tightest
    bend believed). None if too few."""
    if len(pixels) < 3 or np.ptp(pixels.y) < 10:
        return None
    weights = 0.5 + pixels.y / max(float(pixels.y.max()), 1.0)
    fit = np.polyfit(pixels.y, pixels.x, 2, w=weights)
    if abs(fit[0]) <= max_bend:
        return fit
    bend = float(np.copysign(max_bend, fit[0]))
    return np.array([bend, *np.polyfit(pixels.y, pixels.x - bend * pixels.y**2, 1, w=weights)])


def evaluate_fit(fit: Fit, y: NDArray[Any] | float) -> NDArray[np.float64]:
    """x of a fit at rows y."""
    return np.asarray(np.polyval(fit, y), dtype=np.float64)


def histogram_base(mask: NDArray[np.uint8], hint: float, spread: float) -> float:
    """Column of the strongest paint in the lower half near where the line is expected."""
    h, w = mask.shape
    column_sum = mask[h // 2 :].sum(axis=0).astype(np.float64)
    # Prefer peaks near the expected column: weight falls off over `spread` pixels.
    weighted = column_sum * np.exp(-(((np.arange(w) - hint) / spread) ** 2))
    return float(np.argmax(weighted)) if weighted.max() > 0 else hint


def painted_along(
    mask: NDArray[np.uint8], columns: NDArray[np.float64], half_width: int
) -> NDArray[np.bool_]:
    """Whether each row of the bird's-eye `mask` has paint within `half_width` pixels of the
    column given for it: `columns` is (curves, rows), one column per row of each curve (False
    where a curve's column is outside the view)."""
    # Paint within `half_width` of a column is paint at that column of the widened mask.
    wide = cv2.dilate((mask > 0).astype(np.uint8), np.ones((1, 2 * half_width + 1), np.uint8))
    at = np.rint(columns)
    inside = (at >= 0) & (at < mask.shape[1])
    painted = np.zeros(at.shape, bool)
    index = np.broadcast_to(np.arange(at.shape[1], dtype=np.intp)[None, :], at.shape)
    painted[inside] = wide[index[inside], at[inside].astype(np.intp)] > 0
    return painted


def paint_between(
    mask: NDArray[np.uint8],
    left: Fit,
    right: Fit,
    shares: NDArray[np.float64],
    half_width: int,
) -> tuple[float, float]:
    """The curve between two lines (at one of `shares` of the way from `left` to `right`) that
    has paint within `half_width` pixels in the most rows, and that share of rows: a line inside
    a lane means the two lines bound two lanes."""
    rows = np.arange(mask.shape[0], dtype=np.float64)
    xl, xr = evaluate_fit(left, rows), evaluate_fit(right, rows)
    columns = xl[None, :] + shares[:, None] * (xr - xl)[None, :]  # (shares, rows)
    coverage = painted_along(mask, columns, half_width).mean(axis=1)
    best = int(np.argmax(coverage))
    return float(shares[best]), float(coverage[best])


def paint_inside(
    mask: NDArray[np.uint8],
    left: Fit,
    right: Fit,
    margin: float,
    hidden: NDArray[np.bool_] | None = None,
    along: Fit | None = None,
) -> float:
    """The share of a lane's inside (between its two lines, `margin` pixels in from each,
    outside `hidden` and twice `margin` off a line `along` it: a double line's other stripe
    too) that the bird's-eye `mask` paints: about none on a lane, which a pedestrian
    crossing's bars paint across."""
    h, w = mask.shape
    rows = np.arange(h, dtype=np.float64)
    shown = np.ones((h, w), bool) if hidden is None else ~hidden
    # Per row, the columns c with lo < c < hi: from floor(lo) + 1 up to ceil(hi), exclusive.
    first = np.clip(np.floor(evaluate_fit(left, rows) + margin) + 1, 0, w).astype(np.intp)
    end = np.clip(np.ceil(evaluate_fit(right, rows) - margin), 0, w).astype(np.intp)
    end = np.maximum(end, first)
    band = None
    if along is not None:  # ... but those with |c - a| <= 2 margin: ceil(a - 2m) to floor(a + 2m)
        a = evaluate_fit(along, rows)
        b0 = np.clip(np.ceil(a - 2 * margin), first, end).astype(np.intp)
        b1 = np.clip(np.floor(a + 2 * margin) + 1, first, end).astype(np.intp)
        band = (b0, np.maximum(b1, b0))
    index = np.arange(h)

    def counted(pixels: NDArray[np.bool_]) -> int:
        """The `pixels` in those columns, by row sums of each row's running count."""
        running = np.zeros((h, w + 1), np.int32)
        np.cumsum(pixels, axis=1, out=running[:, 1:])
        total = running[index, end] - running[index, first]
        if band is not None:
            total -= running[index, band[1]] - running[index, band[0]]
        return int(total.sum())

    area = counted(shown)
    return counted(mask.astype(bool) & shown) / area if area else 0.0


def window_search(
    paint: Paint, base_x: float, windows: int, margin: int, min_pixels: int
) -> LinePixels:
    """Follow one line upwards in stacked windows, re-centring where enough pixels are found."""
    h = paint.mask.shape[0]
    ys, xs = paint.ys, paint.xs
    height = h // windows
    centre = base_x
    step = 0.0
    chosen: list[NDArray[np.intp]] = []
    boxes = []
    for i in range(windows):
        y2 = h - i * height
        y1 = y2 - height
        x1, x2 = int(centre - margin), int(centre + margin)
        boxes.append((x1, y1, x2, y2))
        inside = np.flatnonzero((ys >= y1) & (ys < y2) & (xs >= x1) & (xs < x2))
        chosen.append(inside)
        if len(inside) >= min_pixels:
            new_centre = float(xs[inside].mean())
            step = new_centre - centre if i else 0.0
            centre = new_centre
        centre += step * 0.5  # follow a curve through gaps in dashed lines
    index = np.concatenate(chosen) if chosen else np.zeros(0, np.intp)
    return LinePixels(xs[index].astype(np.float64), ys[index].astype(np.float64), tuple(boxes))


def prior_search(paint: Paint, prior: Fit, margin: int) -> LinePixels:
    """Pixels within `margin` of a previous fit."""
    ys, xs = paint.ys, paint.xs
    inside = np.abs(xs - evaluate_fit(prior, ys)) < margin
    return LinePixels(xs[inside].astype(np.float64), ys[inside].astype(np.float64))


@dataclass(frozen=True)
class LanePrior:
    """What the last frames say about the lane, to steady a fit where the paint is thin.

    heading: slope dx/dy of the lane's centre at the bottom row; the car turns slowly.
    near_width: lane width in pixels at the bottom row, which pitch changes least.
    """

    heading: float
    near_width: float
    heading_weight: float
    near_width_weight: float


def fit_lane(
    left: LinePixels,
    right: LinePixels,
    rows: float,
    outlier_px: float,
    prior: LanePrior | None = None,
    max_bend: float = np.inf,
) -> tuple[Fit, Fit]:
    """Fit both lines at once: shared curvature and heading, own position, a linear width change.

    left:  x = a y^2 + (b - e/2) y + (c - d/2);  right: x = a y^2 + (b + e/2) y + (c + d/2).
    Lane lines are parallel on the road, so a solid line steadies the fit of a dashed one. Each
    side weighs the same in total (near rows more), and one pass drops outlying pixels. A prior
    adds two weak pseudo-observations, so a dash gap near the camera cannot swing the near end.
    A fit bending more than `max_bend` (|a|) is refitted with a at that bound: the tightest bend
    believed, the lines' other terms fitted to it.
    """
    ys = np.concatenate([left.y, right.y])
    xs = np.concatenate([left.x, right.x])
    side = np.concatenate([np.full(len(left), -0.5), np.full(len(right), 0.5)])
    weights = np.concatenate(
        [np.full(len(left), 1.0 / max(len(left), 1)), np.full(len(right), 1.0 / max(len(right), 1))]
    )
    weights *= 0.5 + ys / rows
    design = np.stack([ys**2, ys, np.ones_like(ys), side, side * ys], axis=1)
    if prior is not None:
        # rows * centre slope at the bottom = rows * heading;  width at the bottom = near_width.
        prior_rows = np.array([[2 * rows**2, rows, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0, rows]])
        prior_targets = np.array([rows * prior.heading, prior.near_width])
        prior_sw = np.sqrt([prior.heading_weight, prior.near_width_weight])

    def solve(keep: NDArray[np.bool_], bend: float | None = None) -> NDArray[np.float64]:
        """The weighted least-squares parameters on the `keep` pixels (a fixed at `bend`)."""
        sw = np.sqrt(weights[keep])
        a_mat, b_vec = design[keep] * sw[:, None], xs[keep] * sw
        if prior is not None:
            a_mat = np.vstack([a_mat, prior_rows * prior_sw[:, None]])
            b_vec = np.concatenate([b_vec, prior_targets * prior_sw])
        if bend is None:
            return np.asarray(np.linalg.lstsq(a_mat, b_vec, rcond=None)[0], np.float64)
        rest = np.linalg.lstsq(a_mat[:, 1:], b_vec - a_mat[:, 0] * bend, rcond=None)[0]
        return np.concatenate([[bend], rest])

    keep = used = np.ones(len(ys), bool)
    params = np.zeros(5)
    for _ in range(2):
        used = keep
        params = solve(used)
        keep = np.abs(design @ params - xs) < outlier_px
        if keep.sum() < 10:
            break
    if abs(params[0]) > max_bend:
        params = solve(used, float(np.copysign(max_bend, params[0])))
    a, b, c, d, e = params
    return np.array([a, b - e / 2, c - d / 2]), np.array([a, b + e / 2, c + d / 2])
