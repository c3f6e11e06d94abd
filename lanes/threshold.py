"""Binary lane mask on the bird's-eye image from colour and morphological gradient.

In the bird's-eye view a lane line is a thin vertical stripe of known width, brighter (white) or
more yellow than the road on both sides. A horizontal top-hat (the image minus its opening with a
window a few line widths wide) keeps exactly such stripes, on dark asphalt, bright concrete and in
shadow alike, while broad bright areas, shadow edges and dark tar seams give nothing.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from lanes.config import LaneConfig


def tophat_kernel(line_width_px: float) -> NDArray[np.uint8]:
    """A 1-row structuring element about three line widths wide (odd)."""
    width = max(3, round(3 * line_width_px) | 1)
    return np.ones((1, width), np.uint8)


def least_white(lightness: NDArray[np.uint8], config: LaneConfig) -> float:
    """The least lightness of white paint on this bird's-eye picture: the configured one where the
    road is as light as the tuned camera's or lighter; on a darker road (dusk, an underexposed
    camera) that much lighter than the road's median, as paint is though not as light, and on a
    road darker than the tuned asphalt less so, in proportion (dim light narrows every
    difference); never under the dark floor, below which glare and noise pass for paint."""
    road = float(np.median(lightness[::4, ::4]))
    full = config.white_margin_road
    margin = config.white_above_road * (min(1.0, road / full) if full > 0 else 1.0)
    relative = min(config.white_min_l, road + margin)
    return max(config.white_min_l_dark, relative)


def lane_mask(
    birdseye_rgb: NDArray[np.uint8], config: LaneConfig, xm_per_px: float, ym_per_px: float
) -> NDArray[np.uint8]:
    """1 where a pixel looks like white or yellow lane paint, else 0; sizes are set in metres."""
    lab = cv2.cvtColor(birdseye_rgb, cv2.COLOR_RGB2LAB)
    lightness, yellowness = lab[:, :, 0], lab[:, :, 2]
    kernel = tophat_kernel(config.line_width_m / xm_per_px)
    white_contrast = cv2.morphologyEx(lightness, cv2.MORPH_TOPHAT, kernel)
    yellow_contrast = cv2.morphologyEx(yellowness, cv2.MORPH_TOPHAT, kernel)
    white = (white_contrast > config.white_tophat) & (lightness > least_white(lightness, config))
    yellow = (yellow_contrast > config.yellow_tophat) & (yellowness > config.yellow_min_b)
    mask = np.asarray(white | yellow, dtype=np.uint8)
    # Paint runs along the road: a vertical opening drops the flat speckles of concrete texture.
    rows = max(1, round(config.min_paint_m / ym_per_px))
    return np.asarray(cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((rows, 1), np.uint8)))
