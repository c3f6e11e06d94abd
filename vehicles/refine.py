"""Box edges from the picture itself: where a vehicle meets the road.

Heat from square windows says where a vehicle is, not where it ends: a saloon and an SUV heat the
same rows. Below a vehicle lies its shadow and its tyres, darker than the road beyond, so its
bottom edge is the row where the picture brightens most going down across the vehicle's middle.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray


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
    lx0, ly0, lx1, ly1 = live
    for box in out:
        x0, y0, x1, y1 = box
        width, height = x1 - x0, y1 - y0
        top = int(max(ly0, round(y1 - reach[0] * height)))
        bottom = int(min(ly1 - 1, round(y1 + reach[1] * height)))
        left = int(max(lx0, round(x0 + margin * width)))
        right = int(min(lx1, round(x1 - margin * width)))
        if bottom - top < 4 or right - left < 4:
            continue
        strip = cv2.cvtColor(
            np.ascontiguousarray(frame[top : bottom + 1, left:right]), cv2.COLOR_RGB2GRAY
        )
        profile = np.median(strip, axis=1).astype(np.float32).reshape(-1, 1)
        profile = np.asarray(cv2.GaussianBlur(profile, (1, 3), 0), np.float32).ravel()
        rise = profile[2:] - profile[:-2]  # at rows top + 1 .. bottom - 1
        row = int(np.argmax(rise))
        if rise[row] >= min_rise:
            box[3] = float(top + 1 + row)
    return out
