"""Box edges where a vehicle ends, which its heat does not say.

Heat from square windows says where a vehicle is, not where it ends: a saloon and an SUV heat the
same rows. Below a vehicle lies its shadow and its tyres, darker than the road beyond, so its
bottom edge is the row where the picture brightens most going down across the vehicle's middle;
its roof's outline against what lies behind is the row near the heat's top where the picture
changes most across the middle.
Beside the camera's axis a vehicle shows its side too, on the side facing the axis, which windows
trained mostly on rear views heat little: its box reaches further that way.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from vehicles.detections import cut_edges


def snap_bottoms(
    frame: NDArray[np.uint8],
    boxes: NDArray[np.float64],
    live: tuple[int, int, int, int],
    reach: tuple[float, float] = (0.3, 0.3),
    min_rise: float = 8.0,
    margin: float = 0.2,
) -> NDArray[np.float64]:
    """The boxes with each bottom edge moved to the row where the picture, across the box's
    middle (less `margin` of its width at each side), brightens most going down: searched from
    `reach[0]` of the box's height above its bottom to `reach[1]` below, inside the `live` box.
    A box where no row brightens by `min_rise` grey levels (a dark road at night) keeps its
    bottom."""
    out = np.array(boxes, np.float64, copy=True).reshape(-1, 4)
    for box in out:
        found = _strongest_row(frame, box, box[3], reach, margin, live, signed=True)
        if found is not None and found[1] >= min_rise:
            box[3] = float(found[0])
    return out


def snap_tops(
    frame: NDArray[np.uint8],
    boxes: NDArray[np.float64],
    live: tuple[int, int, int, int],
    reach: tuple[float, float] = (0.1, 0.2),
    min_change: float = 20.0,
    margin: float = 0.25,
    min_height: float = 32.0,
) -> NDArray[np.float64]:
    """The boxes with each top edge moved to the row where the picture, across the box's middle
    (less `margin` of its width at each side: a roof is narrower than its car), changes most
    going down: searched from `reach[0]` of the box's height above its top to `reach[1]` below,
    inside the `live` box. A box where no row changes by `min_change` grey levels, cut by the
    live picture's side (its middle is not the car's), or under `min_height` pixels tall (a few
    rows of a far car's roof and window blur into one edge) keeps its top."""
    out = np.array(boxes, np.float64, copy=True).reshape(-1, 4)
    at_side = np.asarray(cut_edges(out, live)[:, [0, 2]].any(axis=1))
    for box, cut in zip(out, at_side, strict=True):
        _, y0, _, y1 = box
        if y1 - y0 < min_height or cut:
            continue
        found = _strongest_row(frame, box, y0, reach, margin, live, signed=False)
        if found is not None and found[1] >= min_change:
            box[1] = float(found[0])
    return out


def _strongest_row(
    frame: NDArray[np.uint8],
    box: NDArray[np.float64],
    row: float,
    reach: tuple[float, float],
    margin: float,
    live: tuple[int, int, int, int],
    signed: bool,
) -> tuple[int, float] | None:
    """The row near `row` (from `reach[0]` of the box's height above it to `reach[1]` below,
    inside `live`) where the median grey level across the box's middle (less `margin` of its
    width at each side) brightens most going down (`signed`) or changes most either way, and
    that change; None where the strip is too small to say."""
    x0, y0, x1, y1 = box
    lx0, ly0, lx1, ly1 = live
    width, height = x1 - x0, y1 - y0
    top = int(max(ly0, round(row - reach[0] * height)))
    bottom = int(min(ly1 - 1, round(row + reach[1] * height)))
    left = int(max(lx0, round(x0 + margin * width)))
    right = int(min(lx1, round(x1 - margin * width)))
    if bottom - top < 4 or right - left < 4:
        return None
    strip = cv2.cvtColor(
        np.ascontiguousarray(frame[top : bottom + 1, left:right]), cv2.COLOR_RGB2GRAY
    )
    profile = np.median(strip, axis=1).astype(np.float32).reshape(-1, 1)
    profile = np.asarray(cv2.GaussianBlur(profile, (1, 3), 0), np.float32).ravel()
    change = profile[2:] - profile[:-2]  # at rows top + 1 .. bottom - 1
    if not signed:
        change = np.abs(change)
    best = int(np.argmax(change))
    return top + 1 + best, float(change[best])


def reach_toward(
    boxes: NDArray[np.float64],
    column: float,
    share: float,
    live: tuple[int, int, int, int],
    motion: NDArray[np.float64] | None = None,
    fast: float = 0.12,
    lead: float = 0.5,
    tolerance: float = 4.0,
) -> NDArray[np.float64]:
    """The boxes, each reaching `share` of its width further towards `column` (the road's
    vanishing column, which the side of a car beside the camera's axis faces), but not past it:
    a box astride it (no side shows) is kept. A box whose `motion` (its centre's px a frame) is
    over `fast` of its width (oncoming traffic) reaches `lead` times its motion the way it moves
    instead: its heat, from the last frames, trails it. A box within `tolerance` px of a side of
    the `live` box keeps its width (it is measured there by another rule); none reaches past it."""
    out = np.array(boxes, np.float64, copy=True).reshape(-1, 4)
    if not len(out):
        return out
    x0, x1 = out[:, 0].copy(), out[:, 2].copy()
    moves = np.zeros(len(out)) if motion is None else np.asarray(motion, np.float64)
    quick = np.abs(moves) > fast * (x1 - x0)
    inside = ~cut_edges(out, live, tolerance)[:, [0, 2]].any(axis=1)
    reach = np.where(quick, lead * np.abs(moves), share * (x1 - x0))
    # Towards the column, not past it; or the way a quick box moves.
    left = inside & np.where(quick, moves < 0, x0 >= column)
    right = inside & np.where(quick, moves > 0, x1 <= column)
    stop_left = np.where(quick, live[0], column)
    stop_right = np.where(quick, live[2], column)
    out[left, 0] = np.maximum(x0[left] - reach[left], stop_left[left])
    out[right, 2] = np.minimum(x1[right] + reach[right], stop_right[right])
    return out
