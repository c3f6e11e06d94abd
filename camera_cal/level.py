"""A camera's roll read off the footage: the lean of the vehicles' rear edges, and the spacing
of the road's lane lines.

The rear of a vehicle ahead is an upright face across the road, nearly parallel to the picture,
and lines parallel to the picture keep their direction in it: its bumper, lights, number plate,
rear window and roof line lie level in a level picture wherever the vehicle is, near or far,
left or right. In a picture turned by a camera mounted askew they lean by the turn. Two lane
lines do not tell it (their lean mixes the turn with where the camera is in its lane), and a
highway has few upright posts (README, A camera mounted askew); but lanes of one width side by
side do: in a level picture every row crosses equally spaced lines at equal steps, whatever
the camera's height, pitch or heading, and a turned picture spreads them on the side it turns
up and packs them on the other (`lattice_turns`).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

Box = tuple[int, int, int, int]


@dataclass(frozen=True)
class RayGrid:
    """Where each pixel of the rays' picture is read in the frame's rows from `top` to `bottom`
    (`cv2.remap`'s maps, their rows counted from `top`), which of them lie inside the live box,
    and how many rows each column has there."""

    xs: NDArray[np.float32]
    ys: NDArray[np.float32]
    top: int
    bottom: int
    inside: NDArray[np.bool_]
    seen: NDArray[np.intp]


@dataclass(frozen=True)
class LatticeConfig:
    """How the road's lane lines give a turn (`lane_lines`, `lattice_turns`, `LaneLattice`).

    The road below the horizon is resampled along rays from its vanishing point: a column per
    `step` of t, the sideways offset per row below the vanishing point (a line on the road
    along it keeps one t: its distance aside over the camera's height), out to `reach` either
    side, over the rows from `top_share` of the live height under the horizon down to
    `bottom_share` above the live picture's bottom (a bonnet's edge). Paint is what a top-hat
    `paint_width` of t wide finds `contrast` grey levels over the road beside it; a line is a
    column painted in `min_cover` of the `min_rows` or more rows it is seen in (`min_paint_rows`
    at least), the most painted within `peak_reach` of t. It is dashed where its paint comes in
    two runs or more (`min_dash_rows` long, `min_gap_rows` apart) over at most `max_dashed` of
    its rows. A turn is sought within `search_deg`, in steps of `search_step_deg`.

    A frame reads a turn where two of its threes of lines agree on one within `pair_deg` (one
    three alone mixes the turn with lanes of unequal width and with a lens's bowing: the US
    winter clip's one three read 3 degrees); a turn is read once `least` of the last `keep`
    frames' turns are in, `share` of them within `agree_deg` of their commonest (a kernel of
    `bandwidth_deg`). The lines are read for the first `frames` frames at most (a road without
    lanes side by side reads none). Measured (README): project_cut_1 and _2 turned 3 degrees
    clockwise read -3.1 and -2.6 from frames 28 and 10; turned anticlockwise their lines beyond
    the next lane spread out of the picture; level, and the eight wild clips, they read none."""

    step: float = 0.02
    reach: float = 9.0
    top_share: float = 0.03
    bottom_share: float = 0.08
    paint_width: float = 0.5
    contrast: float = 40.0
    min_rows: int = 40
    min_paint_rows: int = 10
    min_cover: float = 0.12
    peak_reach: float = 0.24
    max_dashed: float = 0.7
    min_dash_rows: int = 2
    min_gap_rows: int = 3
    search_deg: float = 8.0
    search_step_deg: float = 0.05
    pair_deg: float = 0.6
    least: int = 10
    keep: int = 200
    share: float = 0.6
    agree_deg: float = 0.75
    bandwidth_deg: float = 0.3
    frames: int = 500


@dataclass(frozen=True)
class RoadTurnConfig:
    """When the turns the road's motion reads (the lane stage's advance on either side of its
    view, one a frame) say the picture is turned (`RollReading`).

    The last `keep` are kept, read for the first `frames` frames at most (each costs the lane
    stage two more correlations, 4.3 ms a frame at 720p on the bench machine), and no more
    once `least` of them agree on level (under `LevelConfig.min_roll_deg`: no rule takes
    them). They are taken once `least` are in, their quartiles within `spread_deg` of each
    other. They stand in for the second vehicle where one vehicle's leans read a turn and
    their median, a turn too (`LevelConfig.min_roll_deg` or more off level, the same way), is
    within `LevelConfig.max_spread_deg` of it; alone, where no vehicle gave
    `LevelConfig.least` leans and their median is `alone_deg` or more off level. A frame's
    reading leans on the road's surface either side being as flat and as textured as the
    lane's: a verge or a shoulder of another texture scatters them (the wild clips' rural
    road, India, US winter: quartiles 5-16 degrees apart). Measured (README): the shared clips
    level read -0.3 to 0.7, turned 3 degrees 2.6-3.8 and -2.1 to -3.1; the challenge clips
    -0.9 to -1.5."""

    least: int = 50
    spread_deg: float = 1.0
    alone_deg: float = 2.0
    keep: int = 200
    frames: int = 500


@dataclass(frozen=True)
class LevelConfig:
    """How a box's edges give a lean, and when the leans of many say the picture is turned.

    A box's lean is the commonest direction of its strongest edges within `search_deg` of level
    (the top `strong` share of its gradients, inside `inset` of its width and height off each
    side: the road and background at its rim), in bins of `bin_deg`, refined `passes` times as
    the mean of those within `band_deg` of it; boxes under `min_box_px` across are too coarse,
    and those over `max_box_px` are read shrunk to it (a near car's rear costs no more). The
    picture is taken as turned once `least` leans are in, their median at least
    `min_roll_deg` off level and at most `max_roll_deg`, their quartiles within
    `max_spread_deg` of each other, and the vehicles that gave `vehicle_leans` or more agree
    with it: at least `vehicles` of them, and more than half, with their own median within
    `max_spread_deg` of it. One vehicle's edges can lean on their own (a car seen from its
    side, or turned on a bend: one on the level LA clip leant 2.7 degrees for 21 frames); a
    turned picture turns every vehicle's. Measured (README): the shared clips level read -0.1
    to 0.3, turned 3 degrees 2.9-3.3; LA's leans scatter too far to be taken."""

    search_deg: float = 12.0
    bin_deg: float = 0.5
    band_deg: float = 4.0
    strong: float = 0.2
    inset: float = 0.05
    passes: int = 3
    min_pixels: int = 20
    min_box_px: int = 24
    max_box_px: int = 128
    least: int = 20
    min_roll_deg: float = 1.5
    max_roll_deg: float = 8.0
    max_spread_deg: float = 1.5
    vehicles: int = 2
    vehicle_leans: int = 5
    road: RoadTurnConfig = field(default_factory=RoadTurnConfig)
    lattice: LatticeConfig = field(default_factory=LatticeConfig)


def edge_lean(
    rgb: NDArray[np.uint8], box: tuple[float, float, float, float], config: LevelConfig
) -> float | None:
    """The lean in degrees (anticlockwise positive, rising to the right, as `--roll` counts)
    of the near-level edges inside `box` (x0, y0, x1, y1) of an RGB picture; None when the box
    is too small or shows too few such edges."""
    x0, y0, x1, y1 = box
    dx, dy = (x1 - x0) * config.inset, (y1 - y0) * config.inset
    h, w = rgb.shape[:2]
    c0, r0 = max(round(x0 + dx), 0), max(round(y0 + dy), 0)
    c1, r1 = min(round(x1 - dx), w), min(round(y1 - dy), h)
    if c1 - c0 < config.min_box_px or r1 - r0 < config.min_box_px // 2:
        return None
    grey = cv2.cvtColor(np.ascontiguousarray(rgb[r0:r1, c0:c1]), cv2.COLOR_RGB2GRAY)
    if c1 - c0 > config.max_box_px:  # a near car's rear: its edges lean as they do smaller
        scale = config.max_box_px / (c1 - c0)
        size = (config.max_box_px, max(round((r1 - r0) * scale), 1))
        grey = cv2.resize(grey, size, interpolation=cv2.INTER_AREA)
    # Scharr's kernels: their gradient's direction is truer than Sobel's (which read a step
    # edge turned 5 degrees as 4.5).
    # The crop's outermost pixels are left out: mirrored at the border, their horizontal
    # gradient is 0, so that every one of them read as a level edge (LA's small cars' leans
    # then stayed near level in a turned picture).
    gx = cv2.Scharr(grey, cv2.CV_32F, 1, 0)[1:-1, 1:-1]
    gy = cv2.Scharr(grey, cv2.CV_32F, 0, 1)[1:-1, 1:-1]
    energy = (gx * gx + gy * gy).ravel()
    cut = min(int(len(energy) * (1.0 - config.strong)), len(energy) - 1)
    strong = energy > np.partition(energy, cut)[cut]
    # An edge's lean from level is its gradient's from the vertical, folded into +-90 degrees
    # (of the strong ones alone: most of a box's cost is here).
    lean = (np.degrees(np.arctan2(gx.ravel()[strong], gy.ravel()[strong])) + 90.0) % 180.0 - 90.0
    weight = energy[strong]
    near = np.abs(lean) < config.search_deg
    lean, weight = lean[near], weight[near]
    if len(lean) < config.min_pixels:
        return None
    # The mode of the leans weighed by their energy (bins of `bin_deg`, smoothed over a degree
    # either way: a turned edge's pixel steps scatter them), then the weighted mean of those
    # within `band_deg` of it: a turned picture's edges are found wherever they lean within
    # the search, not pulled towards level.
    bins = round(2 * config.search_deg / config.bin_deg)
    index = np.clip(((lean + config.search_deg) / config.bin_deg).astype(int), 0, bins - 1)
    histogram = np.bincount(index, weight, bins)
    spread = np.arange(-4, 5) * config.bin_deg
    smooth = np.convolve(histogram, np.exp(-0.5 * (spread / 1.0) ** 2), mode="same")
    centre = (int(np.argmax(smooth)) + 0.5) * config.bin_deg - config.search_deg
    for _ in range(config.passes):
        close = np.abs(lean - centre) < config.band_deg
        if np.count_nonzero(close) < config.min_pixels:
            return None
        centre = float(np.sum(lean[close] * weight[close]) / np.sum(weight[close]))
    return centre


def ray_grid(vanishing: tuple[float, float], live: Box, config: LatticeConfig) -> RayGrid:
    """The rays' picture's grid in a frame, inside the `live` box (x0, y0, x1, y1): a column per
    `config.step` of t = (x - vx) / (y - vy) from -`reach` to `reach`, rows as many as 720
    frame rows would give, from under the horizon through the `vanishing` point (vx, vy) down
    to the bonnet's margin (see `LatticeConfig`). Every line on the road along it is a column."""
    vx, vy = vanishing
    x0, y0, x1, y1 = live
    height = y1 - y0
    top = max(vy, y0) + config.top_share * height
    bottom = y1 - config.bottom_share * height
    ts = np.arange(-config.reach, config.reach, config.step)
    count = max(0, round((bottom - top) * 720 / max(height, 1)))
    rows = np.linspace(top, bottom, count) if count else np.zeros(0)
    xs = vx + ts[None, :] * (rows[:, None] - vy)
    ys = np.repeat(rows[:, None], len(ts), axis=1)
    inside = (xs >= x0) & (xs <= x1 - 1)
    first = int(np.floor(top)) if count else 0
    last = int(np.ceil(bottom)) + 2 if count else 0
    return RayGrid(
        xs.astype(np.float32),
        (ys - first).astype(np.float32),
        first,
        last,
        inside,
        np.count_nonzero(inside, axis=0),
    )


def _dashed(painted: NDArray[np.bool_], config: LatticeConfig) -> bool:
    """Whether a line's painted rows (top to bottom) come in two runs or more, apart."""
    step = np.diff(np.concatenate([[0], painted.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(step == 1), np.flatnonzero(step == -1)
    long = stops - starts >= config.min_dash_rows
    starts, stops = starts[long], stops[long]
    return bool(len(starts) >= 2 and np.any(starts[1:] - stops[:-1] >= config.min_gap_rows))


def lane_lines(
    rgb: NDArray[np.uint8], grid: RayGrid, config: LatticeConfig
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The lines on the road of an RGB picture, as their t on the rays' `grid` (`ray_grid`),
    left to right, and whether each is dashed (see `LatticeConfig`)."""
    inside, seen = grid.inside, grid.seen
    if inside.shape[0] < config.min_rows:
        return np.zeros(0), np.zeros(0, bool)
    # Only the rows the rays read are made grey.
    grey = cv2.cvtColor(np.ascontiguousarray(rgb[grid.top : grid.bottom]), cv2.COLOR_RGB2GRAY)
    rays = cv2.remap(grey, grid.xs, grid.ys, cv2.INTER_LINEAR)
    width = max(3, round(config.paint_width / config.step))
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (width, 1))
    paint = (cv2.morphologyEx(rays, cv2.MORPH_TOPHAT, kernel) > config.contrast) & inside
    painted = np.count_nonzero(paint, axis=0)
    cover = np.where(
        (seen >= config.min_rows) & (painted >= config.min_paint_rows),
        painted / np.maximum(seen, 1),
        0.0,
    )
    cover = np.convolve(cover, np.ones(5) / 5, mode="same")
    reach = max(1, round(config.peak_reach / config.step))
    # The most painted within `reach` columns (numpy's window: scipy.ndimage's import alone
    # costs the command's start 0.2 s).
    padded = np.pad(cover, reach, constant_values=-1.0)
    most = np.lib.stride_tricks.sliding_window_view(padded, 2 * reach + 1).max(axis=1)
    peaks = np.flatnonzero((cover >= config.min_cover) & (cover == most))
    peaks = peaks[(peaks >= reach) & (peaks < len(cover) - reach)]
    ts = -config.reach + peaks * config.step
    near = cv2.dilate(paint.view(np.uint8), np.ones((1, 5), np.uint8))  # within 2 columns
    dashed = np.array(
        [
            _dashed(near[inside[:, i], i] > 0, config) and cover[i] <= config.max_dashed
            for i in peaks
        ],
        bool,
    )
    return ts.astype(np.float64), dashed


def _searched_turns(config: LatticeConfig) -> NDArray[np.float64]:
    """The turns (degrees) a turn is sought among: within `search_deg`, `search_step_deg` apart."""
    return np.arange(-config.search_deg, config.search_deg + 1e-9, config.search_step_deg)


def _equal_spacing_turn(ts: NDArray[np.float64], config: LatticeConfig) -> float | None:
    """The turn (degrees anticlockwise) that, taken back, leaves three lines' t (left to right
    or right to left) equally spaced: the one root within the search, or None."""
    turns = np.radians(_searched_turns(config))
    angles = np.arctan(ts)
    back = np.tan(angles[None, :] - turns[:, None])
    gap = (back[:, 1] - back[:, 0]) - (back[:, 2] - back[:, 1])
    roots = np.flatnonzero(np.sign(gap[:-1]) * np.sign(gap[1:]) < 0)
    if len(roots) != 1:
        return None
    k = int(roots[0])
    share = gap[k] / (gap[k] - gap[k + 1])  # where the gap crosses 0 between the two steps
    return float(np.degrees(turns[k] + share * (turns[k + 1] - turns[k])))


def lattice_turns(
    ts: NDArray[np.float64], dashed: NDArray[np.bool_], config: LatticeConfig
) -> list[float]:
    """The turns (degrees anticlockwise, as `--roll` counts) that the lines at `ts` (left to
    right; `lane_lines`) read, one for each three lines side by side whose middle one and
    outer one beyond the car's lane are dashed: the car's own lane's two lines (the nearest
    either side of t = 0) and the next one or two out on either side, each a lane of the
    same width apart on the road. The middle line of three divides two lanes of one way, so it
    is dashed; the road's edge lines and what lies beyond them (a shoulder, a barrier's foot,
    a guard rail's posts) end the count, as any line not dashed does."""
    left, right = np.flatnonzero(ts < 0), np.flatnonzero(ts > 0)
    if not len(left) or not len(right):
        return []
    ego = (int(left[-1]), int(right[0]))
    lane = ts[ego[1]] - ts[ego[0]]
    turns = []
    for inner, outer, beyond in ((ego[0], ego[1], right[1:]), (ego[1], ego[0], left[:-1][::-1])):
        chain = [inner, outer]
        for j in beyond:
            if abs(ts[j] - ts[chain[-1]]) < 0.5 * lane:
                continue  # the same line seen twice
            if not (dashed[chain[-1]] and dashed[j]):
                break
            chain.append(int(j))
            if len(chain) == 4:
                break
        for k in range(len(chain) - 2):
            turn = _equal_spacing_turn(ts[chain[k : k + 3]], config)
            if turn is not None:
                turns.append(turn)
    return turns


def frame_turn(turns: list[float], config: LatticeConfig) -> float | None:
    """One frame's turn: the mean of the two of its threes' `turns` (`lattice_turns`) that
    agree best, where they agree within `pair_deg`; None otherwise."""
    ordered = np.sort(np.asarray(turns, np.float64))
    if len(ordered) < 2:
        return None
    gaps = np.diff(ordered)
    k = int(np.argmin(gaps))
    if gaps[k] > config.pair_deg:
        return None
    return float((ordered[k] + ordered[k + 1]) / 2)


class LaneLattice:
    """History of the turns the lane lines read (`frame_turn`, the last `keep` frames'): the
    picture's turn once most of them agree on one (see `LatticeConfig`)."""

    def __init__(self, config: LatticeConfig | None = None) -> None:
        self.config = config if config is not None else LatticeConfig()
        self._turns: deque[float] = deque(maxlen=self.config.keep)
        self.frames = 0
        self._key: tuple[int, int, Box] | None = None  # the vanishing point and box of `_grid`
        self._grid: RayGrid | None = None

    @property
    def done(self) -> bool:
        """Whether as many frames were read as it reads."""
        return self.frames >= self.config.frames

    def update(self, rgb: NDArray[np.uint8], vanishing: tuple[float, float], live: Box) -> None:
        """Take in one RGB frame's lines, read along rays from the road's `vanishing` point
        (x, y) inside the `live` box."""
        self.frames += 1
        x0, y0, x1, y1 = (int(v) for v in live)
        key = (round(vanishing[0]), round(vanishing[1]), (x0, y0, x1, y1))
        if self._grid is None or self._key != key:
            self._key = key
            self._grid = ray_grid((float(key[0]), float(key[1])), key[2], self.config)
        ts, dashed = lane_lines(rgb, self._grid, self.config)
        turn = frame_turn(lattice_turns(ts, dashed, self.config), self.config)
        if turn is not None:
            self._turns.append(turn)

    @property
    def readings(self) -> int:
        """How many frames' lines gave a turn."""
        return len(self._turns)

    @property
    def turn_deg(self) -> float | None:
        """The turn most of the lines' readings agree on (degrees anticlockwise, unrounded);
        None while fewer than `least` are in or fewer than `share` of them agree."""
        c = self.config
        if len(self._turns) < c.least:
            return None
        turns = np.fromiter(self._turns, np.float64)
        grid = _searched_turns(c)
        density = np.exp(-0.5 * ((grid[:, None] - turns[None, :]) / c.bandwidth_deg) ** 2)
        commonest = grid[int(np.argmax(density.sum(axis=1)))]
        near = np.abs(turns - commonest) <= c.agree_deg
        if near.mean() < c.share:
            return None
        return float(turns[near].mean())


class RollReading:
    """History of the leans of vehicles' boxes (the last `keep`, with the vehicle's track id),
    and of the turns the lane lines read (`LaneLattice`): the picture's turn once the leans,
    and the vehicles, agree on one, or, where they do not read level, once the lines do."""

    def __init__(self, config: LevelConfig | None = None, keep: int = 200) -> None:
        self.config = config if config is not None else LevelConfig()
        self._leans: deque[tuple[int, float]] = deque(maxlen=keep)
        self.lattice = LaneLattice(self.config.lattice)
        self._road: deque[float] = deque(maxlen=self.config.road.keep)  # the road's turns
        self._frames = 0  # frames taken in

    def update(
        self,
        rgb: NDArray[np.uint8],
        boxes: NDArray[np.float64],
        ids: NDArray[np.int_],
        vanishing: tuple[float, float] | None = None,
        live: Box | None = None,
        road_turn: float | None = None,
    ) -> float | None:
        """Take in one frame's vehicle boxes ((n, 4) x0, y0, x1, y1, wholly inside the
        picture) and their track ids, and, given the road's `vanishing` point (x, y), its lane
        lines inside the `live` box (None: the whole picture), and the turn the road's motion
        read in it (`road_turn`, see `RoadTurnConfig`); the turn read so far (see `roll_deg`).
        Once as many leans are in as it keeps, no more are read (as many as found no turn say
        the picture is level), nor lines after `LatticeConfig.frames` frames."""
        h, w = rgb.shape[:2]
        if not self._leans_full:
            for (x0, y0, x1, y1), vehicle in zip(
                np.asarray(boxes, np.float64).reshape(-1, 4), np.asarray(ids), strict=True
            ):
                if x0 <= 0 or y0 <= 0 or x1 >= w or y1 >= h:
                    continue  # cut by the picture's side: its edges may be the picture's
                lean = edge_lean(rgb, (x0, y0, x1, y1), self.config)
                if lean is not None:
                    self._leans.append((int(vehicle), lean))
        if vanishing is not None and not self.lattice.done:
            self.lattice.update(rgb, vanishing, live if live is not None else (0, 0, w, h))
        self._frames += 1
        if road_turn is not None:
            self._road.append(road_turn)
        return self.roll_deg

    @property
    def wants_road(self) -> bool:
        """Whether it takes more of the road's turns (`RoadTurnConfig.keep`, for the first
        `RoadTurnConfig.frames` frames, until they agree on level)."""
        road = self.config.road
        if len(self._road) >= road.keep or self._frames >= road.frames:
            return False
        median = self._road_median()
        return median is None or abs(median) >= self.config.min_roll_deg

    @property
    def _leans_full(self) -> bool:
        return len(self._leans) == self._leans.maxlen

    @property
    def full(self) -> bool:
        """Whether it holds as many leans as it keeps and has read the lines for as long as it
        reads them, or the leans read level (which the lines cannot overrule): enough to have
        found a turn, so a picture they did not find turned may be taken as level."""
        return self._leans_full and (self.lattice.done or self._leans_turn() == 0.0)

    @property
    def readings(self) -> int:
        """How many boxes gave a lean."""
        return len(self._leans)

    @property
    def roll_deg(self) -> float | None:
        """The picture's turn in degrees anticlockwise (the `--roll` that levels it), rounded
        to a tenth; None while too few leans are in, they disagree, or they say level, and the
        lane lines read none (or the leans say level: lanes of unequal width read as a turn),
        nor the road's motion (`_road_turn`). `cue` tells which read it."""
        reading = self._reading()
        return None if reading is None else reading[0]

    @property
    def cue(self) -> str | None:
        """What read the turn `roll_deg` reads: "leans" (the vehicles'), "lines" (the lane
        lines' spacing), "vehicle and road" (one vehicle's leans, the road's motion agreeing),
        "road" (the road's motion alone); None while it reads none."""
        reading = self._reading()
        return None if reading is None else reading[1]

    def _reading(self) -> tuple[float, str] | None:
        """The turn read so far and what read it (`roll_deg`, `cue`): the leans first (level
        ones outweigh the rest), then the lines, then the road's motion."""
        leans = self._leans_turn()
        if leans is not None:
            return None if leans == 0.0 else (leans, "leans")
        lines = self._lines_turn()
        if lines is not None:
            return lines, "lines"
        road = self._road_turn()
        if road is None:
            return None
        return road, "road" if len(self._leans) < self.config.least else "vehicle and road"

    def _road_turn(self) -> float | None:
        """The turn one vehicle's leans read where the road's motion agrees, or the road's
        alone where no vehicle was read (see `RoadTurnConfig`), rounded to a tenth."""
        c, r = self.config, self.config.road
        road = self._road_median()
        if road is None:
            return None
        if len(self._leans) < c.least:
            return round(float(road), 1) if abs(road) >= r.alone_deg else None
        lean = self._leans_median()
        if lean is None or abs(lean) < c.min_roll_deg:
            return None
        # The road must read the picture turned too, and the same way: one vehicle leaning
        # 1.6 degrees on its own (a wider lens bows a car's edges off the middle) is within
        # 1.5 of a level road's 0.5.
        agree = abs(road) >= c.min_roll_deg and road * lean > 0
        return round(float(lean), 1) if agree and abs(lean - road) <= c.max_spread_deg else None

    def _road_median(self) -> float | None:
        """The road's turns' median once `RoadTurnConfig.least` are in, their quartiles within
        `RoadTurnConfig.spread_deg` of each other and it within `max_roll_deg` of level."""
        c, r = self.config, self.config.road
        if len(self._road) < r.least:
            return None
        q1, median, q3 = np.quantile(np.fromiter(self._road, np.float64), [0.25, 0.5, 0.75])
        if q3 - q1 > r.spread_deg or abs(median) > c.max_roll_deg:
            return None
        return float(median)

    def _lines_turn(self) -> float | None:
        """The turn the lane lines read, rounded to a tenth, where it is one to level by."""
        c = self.config
        turn = self.lattice.turn_deg
        if turn is None or not c.min_roll_deg <= abs(turn) <= c.max_roll_deg:
            return None
        return round(turn, 1)

    def _leans_median(self) -> float | None:
        """The leans' median once `least` are in, their quartiles within `max_spread_deg` of
        each other and it within `max_roll_deg` of level; None otherwise. Leans that scatter (a
        coarse picture's small cars) are not taken, however many: LA's level picture would
        read a turn of 1.6 degrees (README)."""
        c = self.config
        if len(self._leans) < c.least:
            return None
        q1, median, q3 = np.quantile([lean for _, lean in self._leans], [0.25, 0.5, 0.75])
        if q3 - q1 > c.max_spread_deg or abs(median) > c.max_roll_deg:
            return None
        return float(median)

    def _leans_turn(self) -> float | None:
        """The turn the vehicles' leans read (0.0: level, their median under `min_roll_deg`
        and close together), or None while they say nothing either way: a turn the vehicles
        that gave `vehicle_leans` leans do not agree on (see `LevelConfig`) is none."""
        c = self.config
        median = self._leans_median()
        if median is None:
            return None
        if abs(median) < c.min_roll_deg:
            return 0.0
        ids, leans = (np.asarray(values) for values in zip(*self._leans, strict=True))
        own = [
            float(np.median(leans[ids == vehicle]))
            for vehicle in np.unique(ids)
            if np.count_nonzero(ids == vehicle) >= c.vehicle_leans
        ]
        agree = sum(abs(lean - median) <= c.max_spread_deg for lean in own)
        if agree < c.vehicles or 2 * agree <= len(own):
            return None
        return round(float(median), 1)
