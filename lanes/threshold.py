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


def lab_picture(rgb: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """An RGB picture in OpenCV's 8-bit CIELAB (lightness, green-red, blue-yellow), which the
    paint readings take."""
    return np.asarray(cv2.cvtColor(rgb, cv2.COLOR_RGB2LAB))


def lane_mask(
    birdseye_rgb: NDArray[np.uint8],
    config: LaneConfig,
    xm_per_px: float,
    ym_per_px: float,
    lab: NDArray[np.uint8] | None = None,
) -> NDArray[np.uint8]:
    """1 where a pixel looks like white or yellow lane paint, else 0; sizes are set in metres.
    `lab`: the picture in OpenCV's 8-bit CIELAB where the caller has it (`crossing_length`
    reads its lightness too)."""
    if lab is None:
        lab = lab_picture(birdseye_rgb)
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


def crossing_length(
    lightness: NDArray[np.uint8], config: LaneConfig, xm_per_px: float, ym_per_px: float
) -> float:
    """The length of road in metres over which a bird's-eye picture's `lightness` (CIELAB's,
    as `lane_mask` reads it) shows a pedestrian crossing: rows where at least `crossing_bars`
    bars of paint `crossing_bar_m` wide lie side by side, `crossing_gap_m` apart. A lane line
    is too thin for a bar, a car or a lit patch too wide and alone, an arrow alone."""
    row, _, _, ym_read = _crossing_runs(lightness, config, xm_per_px, ym_per_px)
    return float(len(np.unique(row)) * ym_read)


def crossing_bars(
    lightness: NDArray[np.uint8], config: LaneConfig, xm_per_px: float, ym_per_px: float
) -> NDArray[np.bool_]:
    """Where `crossing_length` reads a crossing's bars in `lightness` (its pixels, for the
    debug mode's picture)."""
    h, w = lightness.shape
    across, along = _steps(xm_per_px, ym_per_px)
    row, start, end, _ = _crossing_runs(lightness, config, xm_per_px, ym_per_px)
    rows, columns = -(-h // along), -(-w // across)
    edges = np.zeros((rows, columns + 1), np.int32)
    np.add.at(edges, (row, start), 1)
    np.add.at(edges, (row, end), -1)
    read = np.cumsum(edges, axis=1)[:, :columns] > 0
    return np.repeat(np.repeat(read, along, axis=0), across, axis=1)[:h, :w]


def _steps(xm_per_px: float, ym_per_px: float) -> tuple[int, int]:
    """The columns and rows a crossing's bars are read in steps of: about 5 cm across and 15 cm
    along (bars are 2-4 m long; half the pixels at 720 rows)."""
    return max(1, int(0.05 / xm_per_px)), max(1, int(0.15 / ym_per_px))


def _crossing_runs(
    lightness: NDArray[np.uint8], config: LaneConfig, xm_per_px: float, ym_per_px: float
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp], float]:
    """The bars of the rows that show a crossing (see `crossing_length`): each one's row, first
    and past-the-last column in the picture read in `_steps`, and that picture's metres a
    row. The bars are found by a top-hat wide enough to keep them whole (the lane mask's
    keeps only their edges)."""
    across, along = _steps(xm_per_px, ym_per_px)
    lightness = np.ascontiguousarray(lightness[::along, ::across])
    xm_per_px, ym_per_px = xm_per_px * across, ym_per_px * along
    kernel = np.ones((1, max(3, round(2 * config.crossing_bar_m[1] / xm_per_px) | 1)), np.uint8)
    contrast = cv2.morphologyEx(lightness, cv2.MORPH_TOPHAT, kernel)
    paint = (contrast > config.crossing_contrast) & (lightness > least_white(lightness, config))
    rows = max(1, round(config.crossing_bar_m[2] / ym_per_px))
    paint = cv2.morphologyEx(paint.astype(np.uint8), cv2.MORPH_OPEN, np.ones((rows, 1), np.uint8))
    # Each row's runs of paint: where a run starts and ends, in reading order (so paired).
    steps = np.diff(np.pad(paint, ((0, 0), (1, 1))).astype(np.int8), axis=1)
    row, start = np.nonzero(steps == 1)
    _, end = np.nonzero(steps == -1)
    width = (end - start) * xm_per_px
    bar = (width >= config.crossing_bar_m[0]) & (width <= config.crossing_bar_m[1])
    row, start, end = row[bar], start[bar], end[bar]
    none = np.zeros(0, np.intp)
    if len(row) < config.crossing_bars:
        return none, none, none, ym_per_px
    # Neighbouring bars of a row a gap apart are linked; a crossing's row has a chain of
    # `crossing_bars - 1` links or more, whose bars are the crossing's.
    gap = (start[1:] - end[:-1]) * xm_per_px
    linked = (row[1:] == row[:-1]) & (gap >= config.crossing_gap_m[0])
    linked &= gap <= config.crossing_gap_m[1]
    chain = np.cumsum(~linked)  # one number per chain of links (and per break)
    links = np.bincount(chain[linked], minlength=int(chain[-1]) + 1)
    crossing = linked & (links >= config.crossing_bars - 1)[chain]
    # A link's two bars: the one before it and the one after.
    kept = np.zeros(len(row), bool)
    kept[:-1] |= crossing
    kept[1:] |= crossing
    return row[kept], start[kept], end[kept], ym_per_px
