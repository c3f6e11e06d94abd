"""Scene geometry from the footage itself: the live part of the picture and the horizon.

A dashcam's picture may carry black bars (a 4:3 sensor in a 16:9 file, a letterbox), a bonnet
at its bottom and burnt-in captions, and its horizon sits wherever the camera's height and pitch
put it. All are read off the frames: bars are rows and columns that stay black in every frame
seen (but not a black night sky: the road's lines meet at its lower edge); a bonnet is the band
of bottom rows that stays still while the road above it streams past; captions are dense
patches of edges that stay in place, and a mirror or pillar a still patch they outline
(`camera_cal.overlay`); the horizon is the row of the vanishing point of the road's straight
edges (lane lines, kerbs, barriers; on a dim picture, weaker edges), the median over recent
frames, and the caller's default until there is enough evidence. The road's lightness ahead
(dusk, night), and whether a picture has colour at all, are read off the same frames.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from camera_cal.overlay import OverlayTracker

Box = tuple[int, int, int, int]  # x0, y0, x1, y1 (x1, y1 exclusive)
MEASURE_WIDTH = 640


@dataclass(frozen=True)
class SceneGeometry:
    """Where the road can be seen in frames of `size`: the live box and the horizon row."""

    size: tuple[int, int]
    horizon_y: float
    live: Box
    estimated: bool = False  # the horizon came from the footage (not the default)
    bonnet_y: int | None = None  # top row of the bonnet (the live box ends there), if one is seen
    # The road's vanishing point's column (a camera turned sideways, or a picture cut off-centre,
    # puts it off the live box's centre); None until measured.
    vanishing_x: float | None = None
    # Burnt-in captions and logos, glare fixed on the windscreen and parts of one's own car (a
    # mirror, a pillar) inside the live box.
    overlays: tuple[Box, ...] = ()
    # A lane's width (and a car's) in pixels at a row below the horizon, against the tuned
    # camera's: under 1 for a camera mounted higher (a lorry's), over 1 for a lower one.
    ground_scale: float = 1.0
    # The median grey level (0-255) of the road ahead over the last few seconds; None until
    # measured. Daylight asphalt reads 70-150; at dusk it falls under 40.
    road_grey: float | None = None
    # The sensor's grain on the road ahead (the noise's standard deviation in grey levels, as
    # the encoder kept it), the median of the last few seconds; None until measured. The shared
    # and wild clips read 0-0.35, grainy copies 0.6 and up (see `grain`).
    grain: float | None = None
    # The picture has carried no colour in its last few samples (an infrared night camera's, a
    # grey-only export; `monochrome`): the vehicle stage reads it with its grey models.
    monochrome: bool = False


def road_patch(live: Box, horizon_y: float) -> tuple[slice, slice]:
    """The road ahead in a frame: the middle 60 % of the live box's width, from 40 % to 90 % of
    the way from the horizon down to its bottom (road, not sky, bonnet or verges)."""
    x0, y0, x1, y1 = live
    top = max(horizon_y, y0)
    rows = slice(round(top + 0.4 * (y1 - top)), max(round(top + 0.9 * (y1 - top)), y0 + 1))
    columns = slice(round(x0 + 0.2 * (x1 - x0)), max(round(x1 - 0.2 * (x1 - x0)), x0 + 1))
    return rows, columns


def road_grey(grey: NDArray[np.uint8], live: Box, horizon_y: float) -> float:
    """The median grey level of the road ahead (`road_patch`) in a grey frame, every 4th
    pixel."""
    rows, columns = road_patch(live, horizon_y)
    patch = grey[rows, columns][::4, ::4]
    return float(np.median(patch)) if patch.size else 0.0


# The second difference whose mean absolute response over pure noise of deviation s is
# s * 6 / sqrt(pi / 2) (J. Immerkaer, "Fast noise variance estimation", 1996).
_NOISE_KERNEL = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)


def grain(frame: NDArray[np.uint8], live: Box, horizon_y: float, max_width: int = 512) -> float:
    """The standard deviation, in grey levels, of the noise on the road ahead (`road_patch`,
    its middle `max_width` columns at most, at full resolution: grain is a pixel's own) of a
    grey or RGB frame (only the patch is made grey): the second difference's mean response
    over the flatter half of the patch (edges, paint and cars left out)."""
    rows, columns = road_patch(live, horizon_y)
    extra = max(0, columns.stop - columns.start - max_width)
    columns = slice(columns.start + extra // 2, columns.stop - (extra - extra // 2))
    patch = frame[rows, columns]
    if patch.ndim == 3:
        patch = cv2.cvtColor(np.ascontiguousarray(patch), cv2.COLOR_RGB2GRAY)
    patch = patch.astype(np.float32)
    if min(patch.shape) < 8:
        return 0.0
    response = np.abs(cv2.filter2D(patch, -1, _NOISE_KERNEL))[1:-1, 1:-1]
    edges = np.abs(cv2.Sobel(patch, cv2.CV_32F, 1, 0)) + np.abs(cv2.Sobel(patch, cv2.CV_32F, 0, 1))
    flat = edges[1:-1, 1:-1] <= np.median(edges[1:-1, 1:-1])
    return float(np.sqrt(np.pi / 2) / 6 * response[flat].mean())


def monochrome(rgb: NDArray[np.uint8], tolerance: int = 6, max_share: float = 0.005) -> bool:
    """Whether a picture carries no colour (an infrared night camera's, a grey-only export):
    under `max_share` of its pixels (every 8th row and column) have channels more than
    `tolerance` grey levels apart (the codec's rounding leaves a few; a coloured caption on a
    grey picture stays under the share, a night sky's blue does not)."""
    sample = rgb[::8, ::8].astype(np.int16)
    spread = sample.max(axis=2) - sample.min(axis=2)
    return bool(np.mean(spread > tolerance) < max_share)


def scale_height(live_size: tuple[int, int]) -> float:
    """The height of the 16:9 picture a live box of `live_size` (width, height) is taken to be
    cut from: its longer side spans the 16:9 width or its shorter side the height, whichever
    gives more. A flat road does not reveal the focal length, so without a calibration the lens
    is taken as the tuned one: cropped at the top, bottom or sides, scaled or padded, the
    pictures then keep the tuned scale (another lens scales distances by the focal lengths'
    ratio)."""
    long_side, short_side = max(live_size), min(live_size)
    return float(max(long_side * 9 / 16, short_side))


def scale_box(box: Box, factor: float) -> Box:
    """`box` scaled by `factor`, rounded outwards (it still covers what it covered)."""
    x0, y0, x1, y1 = box
    return (
        math.floor(x0 * factor),
        math.floor(y0 * factor),
        math.ceil(x1 * factor),
        math.ceil(y1 * factor),
    )


def live_box(row_max: NDArray[np.uint8], col_max: NDArray[np.uint8], dark: int = 24) -> Box:
    """The box inside the black bars, from the brightest value seen in each row and column
    (a bar is black in every frame; a whole dark frame yields the full box)."""
    rows = np.flatnonzero(row_max > dark)
    cols = np.flatnonzero(col_max > dark)
    if len(rows) == 0 or len(cols) == 0:
        return 0, 0, len(col_max), len(row_max)
    return int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1


def bonnet_row(
    motion: NDArray[np.float64],
    min_height: float = 0.03,
    reach: float = 0.35,
    ratio: float = 0.25,
    min_motion: float = 1.0,
) -> int | None:
    """The top row of a bonnet from `motion`, the typical change of each row of the picture
    between frames a few apart, or None: the highest row, `min_height` to `reach` of the height
    up, from which the rows down to the bottom (but the last 1 %; a tenth may be reflections)
    change less than `ratio` of the road's rows above it. The road streams past a moving camera
    and changes; the bonnet moves with it and does not. The test is strict (a thin, reflective
    bonnet may go unseen) since a still, smooth road must not be taken for a bonnet."""
    h = len(motion)
    k = max(1, round(0.01 * h))
    smooth = np.convolve(np.asarray(motion, np.float64), np.ones(k) / k, mode="same")
    above = max(2, round(0.08 * h))
    first, last = max(above, round((1 - reach) * h)), h - max(1, round(min_height * h))
    if last < first:
        return None
    rows = np.arange(first, last + 1)
    # The road's motion just above each candidate row, and how many rows below it (to the last
    # 1 %) move at least `ratio` of that: at most a tenth may (reflections, the bonnet's edge).
    road = np.median(np.lib.stride_tricks.sliding_window_view(smooth, above), axis=1)[rows - above]
    below = (np.arange(h)[None, :] >= rows[:, None]) & (np.arange(h)[None, :] < h - k)
    moving = (smooth[None, :] >= ratio * road[:, None]) & below
    still = moving.sum(axis=1) <= 0.1 * np.maximum(below.sum(axis=1), 1)
    still &= smooth[rows] < ratio * road  # the bonnet's top row itself too
    found = np.flatnonzero(still & (road >= min_motion))
    return int(rows[found[0]]) if len(found) else None


def edge_gain(part: NDArray[np.uint8], paint_grey: float = 100.0, floor: float = 0.3) -> float:
    """How strong the edges of a dim picture are against daylight's: its brightest paint (the
    99.9th percentile) over `paint_grey`, from `floor` to 1. Lines a third as bright as by day
    (dusk, night, a dark sensor) give edges a third as strong."""
    counts = np.bincount(part.ravel(), minlength=256)
    brightest = int(np.searchsorted(np.cumsum(counts), 0.999 * part.size))
    return float(np.clip(brightest / paint_grey, floor, 1.0))


def road_segments(
    grey: NDArray[np.uint8],
    live: Box,
    top: int,
    hidden: tuple[Box, ...] = (),
    strength: float = 1.0,
) -> NDArray[np.float64]:
    """Straight edge segments (x1, y1, x2, y2) below row `top` inside the live box and outside
    the `hidden` boxes (captions), slanted 20-75 degrees from the horizontal as the road's edges
    are seen ahead. Edges are thresholded in proportion to the picture's brightness
    (`edge_gain`): by day at fixed strengths, on a dim picture at weaker ones; `strength`
    scales them further (paint on pale concrete shows weaker edges than on asphalt)."""
    x0, y0, x1, y1 = live
    top = max(top, y0)
    if y1 - top < 16 or x1 - x0 < 16:
        return np.empty((0, 4))
    part = cv2.GaussianBlur(grey[top:y1, x0:x1], (5, 5), 0)
    gain = edge_gain(part) * strength
    edges = cv2.Canny(part, 60 * gain, 150 * gain)
    # Bar edges and the picture's border are no road edges; nor are a caption's letters.
    edges[:, :3] = edges[:, -3:] = 0
    edges[-3:] = 0
    for hx0, hy0, hx1, hy1 in hidden:
        edges[max(0, hy0 - top) : max(0, hy1 - top), max(0, hx0 - x0) : max(0, hx1 - x0)] = 0
    h = y1 - y0
    found = cv2.HoughLinesP(
        edges, 1, np.pi / 180, 40, minLineLength=max(h // 12, 12), maxLineGap=max(h // 60, 2)
    )
    if found is None:
        return np.empty((0, 4))
    segments = found.reshape(-1, 4).astype(np.float64) + np.array([x0, top, x0, top])
    dx = segments[:, 2] - segments[:, 0]
    dy = segments[:, 3] - segments[:, 1]
    angle = np.degrees(np.arctan2(np.abs(dy), np.abs(dx)))
    return np.asarray(segments[(angle > 20) & (angle < 75)], np.float64)


def vanishing_point(
    segments: NDArray[np.float64], tolerance: float, min_segments: int = 4
) -> NDArray[np.float64] | None:
    """The point nearest to every segment's line (length-weighted least squares, outliers
    down-weighted past `tolerance` pixels), or None with too few segments leaning both ways."""
    if len(segments) < min_segments:
        return None
    dx = segments[:, 2] - segments[:, 0]
    dy = segments[:, 3] - segments[:, 1]
    leaning = np.sign(dx * dy)
    if min((leaning > 0).sum(), (leaning < 0).sum()) < 2:
        return None  # one family of parallel edges fixes no point
    length = np.hypot(dx, dy)
    normals = np.column_stack([dy, -dx]) / length[:, None]
    offsets = (normals * segments[:, :2]).sum(axis=1)
    weights = length
    point = None
    for _ in range(8):
        point = np.linalg.lstsq(normals * weights[:, None], offsets * weights, rcond=None)[0]
        residual = np.abs(normals @ point - offsets)
        weights = length / (1.0 + (residual / tolerance) ** 2)
    assert point is not None
    return np.asarray(point, np.float64)


def horizon_estimates(fps: float, count: int = 5, frame_rate: float = 25.0, least: int = 3) -> int:
    """How many frames' vanishing points make the first horizon in video at `fps` (0: unknown):
    `count` at `frame_rate` and above, at lower rates as many as span the same time, but at least
    `least` (frames further apart are more independent; too few, and one stray line moves the
    median). The estimate keeps improving with every frame after."""
    if fps <= 0:
        return count
    return max(least, min(count, round(count * fps / frame_rate)))


class GroundScale:
    """History for the ground scale from the last `window` lane-width samples (each a lane's
    width against the tuned camera's at the same rows, and whether the lane finder believed that
    lane), once `least` are in. The road does not tell a higher camera from narrower lanes, so
    the scale moves only when the tuned one fails: the median is one no lane has at the current
    scale, outside `plausible` (the lane finder's 2.6-5.6 m over the tuned 3.7 m), and fewer
    than `believed` of the samples' lanes were believed. It then moves to the median, so the
    lanes read as the tuned road's.

    `known` says whether a lane's width in pixels is measured at the current scale: `assumed`
    (the pipeline assumes it for a camera calibrated at the frames' size), or once `confirm`
    samples read a plausible median at it, or the scale moved to theirs. Until then a lane side
    made up at the standard width is a guess at an unknown camera's height (the rural road at
    dusk drew one off the picture in every frame it drew)."""

    def __init__(
        self,
        least: int = 25,
        window: int = 250,
        plausible: tuple[float, float] = (0.7, 1.5),
        believed: float = 0.5,
        confirm: int = 5,
        assumed: bool = False,
    ) -> None:
        self.least = least
        self.plausible = plausible
        self.believed = believed
        self.confirm = confirm
        self._samples: deque[tuple[float, bool]] = deque(maxlen=window)
        self.value = 1.0
        self.known = assumed

    def add(self, sample: float | None, believed: bool = False) -> float:
        """Take in one frame's sample (None: no lane measured) and whether its lane was believed;
        the scale as of it."""
        if sample is not None and sample > 0:
            self._samples.append((sample, believed))
            widths, trusted = np.array(self._samples).T
            median = float(np.median(widths))
            low, high = self.plausible
            implausible = not low <= median / self.value <= high
            if len(self._samples) >= self.least and implausible and trusted.mean() < self.believed:
                self.value = round(median, 3)
                self.known = True
            elif len(self._samples) >= self.confirm and not implausible:
                self.known = True
        return self.value


# The spacing of US highways' lane dashes: a 10 ft dash and a 30 ft gap.
US_DASH_SPACING_M = 12.19


class DashScale:
    """History for the road's length scale from the lane dashes' spacings, each as the bird's-
    eye view read it (the lane stage's `dash_spacings`): the view's metres are right only for
    the lens it assumes, and a flat road does not show the lens's focal length otherwise (a
    longer lens on a stretched road gives the same picture; see the README, A lens read off
    the lane dashes).

    Of the last `window` spacings within `span` metres, once `least` are in: their median, then
    twice the median of those within `near` of it (a dash missed reads twice the spacing, a dash
    the mask broke less than half); read where `agree` of them are that near. The scale is the
    road's `spacing_m` over it, and moves there when it is off the current one by more than
    `tolerance` (once moved off 1, by more than `follow`: the lens is then known to differ, and
    the spacing read settles as more dashes come in) and within `plausible` (a lens 2.2 times
    wider than assumed to 1.4 times longer): the shipped camera's clips read their dashes
    within 5 % of 12.19 m, so its scale stays 1; outside, the dashes are taken for another
    road's (`implausible_m` gives the spacing for a note)."""

    def __init__(
        self,
        spacing_m: float = US_DASH_SPACING_M,
        least: int = 30,
        window: int = 200,
        span: tuple[float, float] = (4.0, 40.0),
        near: float = 0.2,
        agree: float = 0.5,
        tolerance: float = 0.15,
        follow: float = 0.05,
        plausible: tuple[float, float] = (0.45, 1.4),
    ) -> None:
        self.spacing_m = spacing_m
        self.follow = follow
        self.least = least
        self.span = span
        self.near = near
        self.agree = agree
        self.tolerance = tolerance
        self.plausible = plausible
        self._spacings: deque[float] = deque(maxlen=window)
        self.value = 1.0
        self.read_m: float | None = None  # the spacing the view reads, once it agrees

    def reset(self) -> None:
        """Forget the spacings read and the scale (the view's metres changed)."""
        self._spacings.clear()
        self.value, self.read_m = 1.0, None

    @property
    def implausible_m(self) -> float | None:
        """The spacing read where no lens within `plausible` explains it (for a note), else
        None."""
        if self.read_m is None:
            return None
        low, high = self.plausible
        return None if low <= self.spacing_m / self.read_m <= high else self.read_m

    def add(self, spacings: tuple[float, ...] | list[float]) -> float:
        """Take in one frame's spacings (metres of the view); the scale as of them."""
        low, high = self.span
        kept = [s for s in spacings if low <= s <= high]
        if not kept:
            return self.value
        self._spacings.extend(kept)
        if len(self._spacings) < self.least:
            return self.value
        every = np.asarray(self._spacings)
        read = float(np.median(every))
        close = every
        for _ in range(2):
            close = every[np.abs(every / read - 1) <= self.near]
            read = float(np.median(close)) if len(close) else read
        if len(close) < self.agree * len(every):
            return self.value
        self.read_m = read
        scale = self.spacing_m / read
        if abs(scale / self.value - 1) <= (self.tolerance if self.value == 1 else self.follow):
            return self.value
        if self.plausible[0] <= scale <= self.plausible[1]:
            self.value = round(scale, 3)
        return self.value


class SceneTracker:
    """History for the scene geometry: the brightest value seen per row and column (for the
    bars), each row's change between frames `motion_every` apart (for a bonnet), the edges of
    every `overlay_every`-th frame (for captions) and the recent vanishing points (for the
    horizon).

    `default_horizon` is used until `min_estimates` frames gave a vanishing point, and always when
    `fixed_horizon` is set (the user's `--horizon`). The horizon is measured on every frame until
    then, and every `every` frames after (it changes slowly; each costs a few milliseconds).
    With `full_size_first` (the app sets it for an unknown camera, whose stages wait for the
    first horizon), a frame the picture shrunk to `MEASURE_WIDTH` gives no point for is measured
    again at full size until then, and failing that with edges `weak_edges` as strong.
    The stages' placement follows the horizon and live box in steps of `settle` of the height,
    and the vanishing point's column in steps of `settle_x` of the live width (a bend ahead
    moves it by a few per cent; a camera turned sideways by more).
    The road turns under the camera at a junction or a bend's end: where the last `turn[0]`
    estimates lie within `turn[1]` of the live width of their median, and it is over `turn[2]`
    from the window's median, the older estimates are dropped, so the column follows the new
    road at once (a median of 60 estimates took about 7 s to cross over).
    `fixed_scale` is the scale height of a calibrated lens; without it the live box gives it.
    The ground scale is learned from the lane stage's width samples (`observe_lane_width`;
    `ground` sets how), the road's length scale from its dash spacings (`observe_dashes`;
    `dashes` sets how, None: not read). Every `light_every` frames the road's grey level and
    grain are sampled (their medians over `light_window` samples), and whether the live
    picture has colour: it is monochrome once `colour_samples` samples in a row had none (a
    camera switching to infrared at night is read so a fraction of a second after; one sample
    with colour ends it).
    """

    def __init__(
        self,
        size: tuple[int, int],
        default_horizon: float,
        fixed_horizon: float | None = None,
        window: int = 60,
        min_estimates: int = 5,
        every: int = 3,
        settle: float = 0.015,
        fixed_scale: float | None = None,
        motion_every: int = 3,
        motion_window: int = 60,
        bonnet_every: int = 10,
        settle_x: float = 0.03,
        overlay_every: int = 5,
        ground: GroundScale | None = None,
        light_every: int = 5,
        light_window: int = 15,
        colour_samples: int = 3,
        full_size_first: bool = False,
        weak_edges: float = 0.6,
        dashes: DashScale | None = None,
        turn: tuple[int, float, float] = (8, 0.04, 0.06),
    ) -> None:
        self.size = size
        self.turn = turn
        self.weak_edges = weak_edges
        self.ground = ground if ground is not None else GroundScale()
        self.dashes = dashes
        self.fixed_scale = fixed_scale
        self.default_horizon = default_horizon
        self.full_size_first = full_size_first
        self.fixed_horizon = fixed_horizon
        self.min_estimates = min_estimates
        self.every = every
        self.settle = settle
        self.settle_x = settle_x
        self._estimates: deque[tuple[float, float]] = deque(maxlen=window)  # (x, y)
        self._row_max = np.zeros(size[1], np.uint8)
        self._col_max = np.zeros(size[0], np.uint8)
        self._count = 0
        self.motion_every = motion_every
        self.bonnet_every = bonnet_every
        self._motion: deque[NDArray[np.float64]] = deque(maxlen=motion_window)
        self._previous: NDArray[np.int16] | None = None
        self._bonnet: int | None = None
        self._samples = 0
        # Vanishing points above a black top band, and whether the band was found to be sky.
        self._sky_votes: deque[tuple[float, float]] = deque(maxlen=window)
        self._sky_top = False
        # Captions and the horizon are measured on the picture at most MEASURE_WIDTH wide.
        self._scale = min(1.0, MEASURE_WIDTH / size[0])
        self._small = (max(1, round(size[0] * self._scale)), max(1, round(size[1] * self._scale)))
        self.overlay_every = overlay_every
        self._overlays = OverlayTracker(self._small)
        self._captions: tuple[Box, ...] = ()  # the overlays found, in the frame's pixels
        self._current = SceneGeometry(
            size, fixed_horizon if fixed_horizon is not None else default_horizon, self._box()
        )
        self._placed = (self._current.horizon_y, self._current.live, self._current.live)
        self._placed_x: float | None = None  # the vanishing point's column, placed on its own
        self.light_every = light_every
        self._greys: deque[float] = deque(maxlen=light_window)  # the road's recent grey levels
        self._grains: deque[float] = deque(maxlen=light_window)  # ... and grain
        # Whether each of the last few samples of the live picture had no colour.
        self._colourless: deque[bool] = deque(maxlen=colour_samples)
        # The geometry and placement a look ahead gave, until the horizon's own estimate stands.
        self._ahead: tuple[SceneGeometry, dict[str, Any]] | None = None

    def _picture(self) -> Box:
        """The box inside the bars."""
        if not self._count:
            return 0, 0, self.size[0], self.size[1]
        x0, y0, x1, y1 = live_box(self._row_max, self._col_max)
        return x0, 0 if self._sky_top else y0, x1, y1

    def _box(self) -> Box:
        """The live box: inside the bars and above the bonnet."""
        x0, y0, x1, y1 = self._picture()
        if self._bonnet is not None and y0 + (y1 - y0) // 2 < self._bonnet < y1:
            y1 = self._bonnet
        return x0, y0, x1, y1

    def _track_motion(self, grey: NDArray[np.uint8]) -> None:
        """Add how much each row changed since the last sample (every 4th column inside the
        bars); every `bonnet_every` samples, place the bonnet from the median change."""
        sample = grey[:, ::4].astype(np.int16)
        previous, self._previous = self._previous, sample
        if previous is None:
            return
        x0, y0, x1, y1 = self._picture()
        columns = slice(-(-x0 // 4), max(-(-x0 // 4) + 1, x1 // 4))
        self._motion.append(np.abs(sample[:, columns] - previous[:, columns]).mean(axis=1))
        self._samples += 1
        if self._samples % self.bonnet_every == 0:
            profile = np.median(np.stack(self._motion), axis=0)[y0:y1]
            top = bonnet_row(profile)
            # A bonnet does not go away (a still road, the car stopped, only hides it) nor grow:
            # its top is the highest row found still while the road moved.
            if top is not None:
                self._bonnet = min(y0 + top, self._bonnet or y1)

    def take_horizon(self, other: SceneTracker) -> None:
        """Until this tracker's own horizon stands, give the stages (`update`'s geometry, the
        `placement`) the one `other` estimated off the frames this one is about to take in
        (see `app.pipeline.Pipeline.look_ahead`). The same frames then give this one the same
        estimate, and its history is as without: measured under the default horizon, as
        `other`'s was (a horizon given instead moves where the edges are looked for, and the
        LA clip's first estimate then fell 110 rows low)."""
        self._ahead = (other.current, other.placement)

    @property
    def current(self) -> SceneGeometry:
        """The geometry as of the last frame."""
        if self._ahead is None:
            return self._current
        ahead, _ = self._ahead
        return replace(
            self._current,
            horizon_y=ahead.horizon_y,
            vanishing_x=ahead.vanishing_x,
            estimated=ahead.estimated,
        )

    def update(
        self, rgb: NDArray[np.uint8], decoded: NDArray[np.uint8] | None = None
    ) -> SceneGeometry:
        """Take in one frame; the geometry as of it. Its grain is read off the frame as
        `decoded`, before undistortion, when given: interpolating pixels smooths grain away
        unevenly (the shared clips with grain of 0.7 read 0.45 undistorted)."""
        grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        # Bars: sample every 4th row and column (bars are wide; this costs ~1 ms).
        np.maximum(self._row_max, grey[:, ::4].max(axis=1), out=self._row_max)
        np.maximum(self._col_max, grey[::4].max(axis=0), out=self._col_max)
        if self._count % self.motion_every == 0:
            self._track_motion(grey)
        # Every frame until the first estimate stands (the stages use the default until then),
        # then every few.
        due = self._count % self.every == 0 or len(self._estimates) < self.min_estimates
        live = self._box() if due else self._current.live
        sampled = self._count % self.overlay_every == 0
        small = self._shrink(grey) if sampled or (self.fixed_horizon is None and due) else None
        if sampled and small is not None:
            top = round(self._current.horizon_y * self._scale)
            found = self._overlays.update(small, top, scale_box(live, self._scale))
            self._captions = tuple(scale_box(box, 1 / self._scale) for box in found)
        # Those in the live box (the bonnet's edge below it is no caption, and no road is there).
        overlays = tuple(b for b in self._captions if b[1] < live[3] and b[3] > live[1])
        if self.fixed_horizon is None and due and small is not None:
            before = len(self._estimates)
            pointed = self._measure(small, self._scale, live, overlays)
            # While the first horizon waits, a frame the shrunk picture gives no point for is
            # measured at full size: a camera pitched up sees only the road's far part, whose
            # dashes shrink below the segments' length (the first horizon took 21 frames).
            waiting = self.full_size_first and before < self.min_estimates
            if waiting and len(self._estimates) == before and self._scale < 1:
                pointed = self._measure(grey, 1.0, live, overlays) or pointed
            # ... and where neither gave a point (nor a vote for a night sky), with weaker edges:
            # on pale concrete the yellow line is hardly darker or lighter than the road, and
            # the first horizon took 39 frames (README). One point a frame at most.
            if waiting and not pointed:
                self._measure(small, self._scale, live, overlays, self.weak_edges)
        if self._count % self.light_every == 0:
            self._greys.append(road_grey(grey, live, self._current.horizon_y))
            source = grey if decoded is None else decoded
            self._grains.append(grain(source, live, self._current.horizon_y))
            x0, y0, x1, y1 = live
            self._colourless.append(monochrome(rgb[y0:y1, x0:x1]))
        self._count += 1
        vanishing_x = None
        if self.fixed_horizon is not None:
            horizon, estimated = self.fixed_horizon, False
        elif len(self._estimates) >= self.min_estimates:
            xs, ys = np.array(self._estimates).T
            horizon, estimated = float(np.median(ys)), True
            vanishing_x = float(np.median(xs))
        else:
            horizon, estimated = self.default_horizon, False
        bonnet = self._bonnet if live[3] == self._bonnet else None
        self._current = SceneGeometry(
            self.size,
            horizon,
            live,
            estimated,
            bonnet,
            vanishing_x,
            overlays,
            self.ground.value,
            float(np.median(self._greys)) if self._greys else None,
            float(np.median(self._grains)) if self._grains else None,
            len(self._colourless) == self._colourless.maxlen and all(self._colourless),
        )
        tolerance = self.settle * self.size[1]
        placed_horizon, placed_live, _ = self._placed
        moved = abs(horizon - placed_horizon) > tolerance or any(
            abs(a - b) > tolerance for a, b in zip(live, placed_live, strict=True)
        )
        if moved:
            self._placed = (horizon, live, self._picture())
        # The column follows in steps of its own (from the live centre, where the stages put it
        # without one): it places the lanes' warp, not the vehicle bands.
        placed_x = (live[0] + live[2]) / 2 if self._placed_x is None else self._placed_x
        if vanishing_x is not None and abs(vanishing_x - placed_x) > self.settle_x * (
            live[2] - live[0]
        ):
            self._placed_x = vanishing_x
        if estimated:
            self._ahead = None
        return self.current

    def observe_lane_width(self, sample: float | None, believed: bool = False) -> None:
        """Take in the lane stage's width sample of the last frame (None: none measured) and
        whether the lane finder believed that lane. Where it moves the ground scale, the view's
        metres change with it, and the road's length is read afresh."""
        before = self.ground.value
        if self.ground.add(sample, believed) != before and self.dashes is not None:
            self.dashes.reset()

    def observe_dashes(self, spacings: tuple[float, ...]) -> None:
        """Take in the dash spacings the lane stage completed in the last frame."""
        if self.dashes is not None:
            self.dashes.add(spacings)

    @property
    def length(self) -> tuple[float, float | None]:
        """The road's length scale and the dash spacing the view reads (see `DashScale`): 1 and
        None where the dashes are not read."""
        if self.dashes is None:
            return 1.0, None
        return self.dashes.value, self.dashes.read_m

    @property
    def lane_width_known(self) -> bool:
        """Whether the lanes' width in pixels is known at the ground scale (see GroundScale)."""
        return self.ground.known

    @property
    def placement(self) -> dict[str, Any]:
        """The horizon, vanishing point's column, live box, scale height and ground scale as the
        stages place their work by (their `process` keywords): they follow the estimate in steps
        (`settle`, `settle_x`; the ground scale moves only when the lanes need it), so its
        wobble neither restarts the lanes' history nor moves the vehicle bands; the column is
        None (the live centre) until it is that far off the centre."""
        horizon, live, (x0, y0, x1, y1) = self._placed
        placed_x = self._placed_x
        if self._ahead is not None:
            horizon, placed_x = self._ahead[1]["horizon_y"], self._ahead[1]["vanishing_x"]
        return {
            "horizon_y": horizon,
            "vanishing_x": placed_x,
            "live": live,
            "overlays": self._current.overlays,
            # The scale is the picture's inside the bars: a bonnet hides road, not lens.
            "scale_height": scale_height((x1 - x0, y1 - y0))
            if self.fixed_scale is None
            else self.fixed_scale,
            "ground_scale": self.ground.value,
        }

    def _shrink(self, grey: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """The grey picture at most MEASURE_WIDTH wide (as exact for edges, four times cheaper
        on HD)."""
        if self._scale >= 1.0:
            return grey
        return np.asarray(
            cv2.resize(grey, None, fx=self._scale, fy=self._scale, interpolation=cv2.INTER_AREA)
        )

    def fits(self, rgb: NDArray[np.uint8], tolerance: tuple[float, float] = (0.03, 0.05)) -> bool:
        """Whether the road in frame `rgb` meets where this scene's does: its edges' vanishing
        point within `tolerance` (shares of the height and of the width) of the estimated
        horizon and column. False before an estimate, and where the frame gives no point. (At
        a cut in the footage: the same camera goes on, or another's picture starts.)"""
        current = self._current
        if not current.estimated or current.vanishing_x is None:
            return False
        grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        point = self._point(self._shrink(grey), self._scale, current.live, current.overlays)
        if point is None:
            return False
        x, y = point
        return (
            abs(y - current.horizon_y) <= tolerance[0] * self.size[1]
            and abs(x - current.vanishing_x) <= tolerance[1] * self.size[0]
        )

    def _point(
        self,
        small: NDArray[np.uint8],
        scale: float,
        live: Box,
        overlays: tuple[Box, ...],
        strength: float = 1.0,
    ) -> tuple[float, float] | None:
        """The vanishing point (x, y) in frame pixels of the road's edges outside the
        `overlays`, in the live box below the current horizon (`small`: the picture shrunk by
        `scale`; edges at `strength`, see `road_segments`), or None."""
        x0, y0, x1, y1 = (round(v * scale) for v in live)
        hidden = tuple(scale_box(box, scale) for box in overlays)
        h = y1 - y0
        # Edges from a little below the current horizon down: the road, not the sky.
        top = round(max(self._current.horizon_y * scale, y0 + 0.2 * h) + 0.05 * h)
        segments = road_segments(small, (x0, y0, x1, y1), top, hidden, strength)
        point = vanishing_point(segments, tolerance=0.02 * h)
        if point is None or not x0 <= point[0] < x1:
            return None
        return float(point[0]) / scale, float(point[1]) / scale

    def _follow_turn(self, width: float) -> None:
        """Drop the estimates before the last `turn[0]` where those agree on a column off the
        window's (see the class): the road ahead turned."""
        count, agree, away = self.turn
        if len(self._estimates) <= count:
            return
        xs = np.array([x for x, _ in self._estimates])
        recent = float(np.median(xs[-count:]))
        if (
            np.abs(xs[-count:] - recent).max() <= agree * width
            and abs(recent - float(np.median(xs))) > away * width
        ):
            for _ in range(len(xs) - count):
                self._estimates.popleft()

    def _measure(
        self,
        small: NDArray[np.uint8],
        scale: float,
        live: Box,
        overlays: tuple[Box, ...],
        strength: float = 1.0,
    ) -> bool:
        """Add this frame's vanishing point, when the road's edges outside the `overlays` give
        one (`small`: the picture shrunk by `scale`; edges at `strength`), to the estimates or
        to the votes for a night sky; whether it was either."""
        estimate = self._point(small, scale, live, overlays, strength)
        if estimate is None:
            return False
        _, y0, _, y1 = (round(v * scale) for v in live)  # as the shrunk picture's rows
        h = y1 - y0
        y = estimate[1] * scale
        if y0 + 0.15 * h <= y <= y0 + 0.8 * h:
            self._estimates.append(estimate)
            self._follow_turn(live[2] - live[0])
            return True
        if y0 > 0 and 0.15 * y1 <= y < y0 + 0.15 * h and not self._sky_top:
            # The road's lines meet in or just under a black band at the top: no bar leaves
            # the horizon there, a night sky does. Once the band's votes outnumber the
            # estimates, it is picture (and the votes are estimates).
            self._sky_votes.append(estimate)
            if len(self._sky_votes) >= max(self.min_estimates, len(self._estimates) + 1):
                self._sky_top = True
                self._estimates.extend(self._sky_votes)
            return True
        return False
