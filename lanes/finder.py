"""The lane stage: mask, bird's-eye search, `Line` histories, checks, measurements, record."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from lanes.config import LaneConfig
from lanes.dashes import DashTrack, near_ends
from lanes.line import Line
from lanes.measure import (
    camera_from,
    carried_fit,
    implausible_lane,
    lane_figures,
    lane_widths,
)
from lanes.motion import RoadMotion, SideMotion, turn_from_advances
from lanes.perspective import BirdsEye, birdseye_for
from lanes.search import (
    Fit,
    LanePrior,
    LinePixels,
    Paint,
    evaluate_fit,
    fit_lane,
    fit_line,
    histogram_base,
    paint_between,
    paint_inside,
    painted_along,
    prior_search,
    window_search,
)
from lanes.threshold import crossing_bars, crossing_length, lab_picture, lane_mask

Boxes = tuple[tuple[int, int, int, int], ...]  # x0, y0, x1, y1 in the frame
MIDDLE_SHARES = np.linspace(0.3, 0.7, 17)  # where between two lines a middle line is looked for
MIDDLE = (0.35, 0.65)  # where such a line makes the two lines bound two lanes of a width
ALONG_SHARES = np.linspace(0.1, 0.9, 33)  # where a line along a lane's inside is looked for


@dataclass(frozen=True, eq=False)
class LaneEstimate:
    """The ego lane in one frame: boundaries in undistorted-frame pixels and measurements."""

    left: NDArray[np.float64]  # (n, 2) x, y from the frame bottom up to the search region top
    right: NDArray[np.float64]
    curvature_m: float  # radius in metres; inf on a straight road
    offset_m: float
    left_fit: Fit  # bird's-eye fits, x = a y^2 + b y + c
    right_fit: Fit
    width_m: float = math.nan  # between the boundaries at the bottom row

    def read_in(
        self, view: BirdsEye, measured: BirdsEye, road_x: float | None, straight_m: float
    ) -> LaneEstimate:
        """This lane, found in `view`, with its radius, offset and width read in `measured`: the
        same warp placed at the horizon as estimated, where the stages are placed in steps off
        it (see `carried_fit`). Its boundaries and fits stay the view's, as drawn and tracked;
        `road_x` is the column the road runs to, as in `LaneFinder.process`."""
        left, right = (carried_fit(f, view, measured) for f in (self.left_fit, self.right_fit))
        slant = 0.0 if road_x is None else measured.slant_to(road_x)
        radius, offset, width = lane_figures(left, right, measured, slant, straight_m)
        return replace(self, curvature_m=radius, offset_m=offset, width_m=width)


@dataclass(frozen=True, eq=False)
class LaneDebug:
    """Intermediates of one frame for the debug mode."""

    birdseye: NDArray[np.uint8]
    mask: NDArray[np.uint8]
    left_pixels: LinePixels
    right_pixels: LinePixels
    crossing: NDArray[np.bool_] | None = None  # a pedestrian crossing's bars, where one was read


@dataclass(frozen=True, eq=False)
class LaneResult:
    """What the lane stage found in a frame (lane None when there is none yet)."""

    lane: LaneEstimate | None
    debug: LaneDebug | None = None
    status: tuple[str, ...] = field(default_factory=tuple)
    advance_m: float | None = None  # how far the road moved towards the camera since last frame
    # The lane's width this frame (its two lines fitted and parallel, whether believed or not)
    # against the tuned camera's at the same rows: what the scene learns the ground scale from.
    width_sample: float | None = None
    # Both lines of that sample passed the checks this frame, and it is their lane's width, not
    # half of a lane of two (the lane drawn is not one of those halves).
    width_believed: bool = False
    # The spacings of the dashes along this frame's dashed lines, in the view's metres (see
    # lanes/dashes.py): a lens other than the one the view assumes reads them longer or shorter.
    dash_spacings: tuple[float, ...] = ()
    # The turn of the picture (degrees anticlockwise) that the road's advance on the view's
    # two sides read this frame (`lanes.motion.turn_from_advances`), where it was asked for.
    road_turn_deg: float | None = None


class LaneFinder:
    """Finds the ego lane in every frame, keeping a `Line` history per side."""

    def __init__(self, config: LaneConfig | None = None, keep_debug: bool = False) -> None:
        self.config = config if config is not None else LaneConfig()
        self.keep_debug = keep_debug
        self.fps = 0.0  # the video's frame rate; 0: the one the config's counts are for
        self.left, self.right, self.motion = self._fresh_history()
        self.dashes = self._fresh_dashes()
        self.sides: SideMotion | None = None  # the two sides' motion, while a turn is read
        self._view: BirdsEye | None = None

    def _fresh_lines(self) -> tuple[Line, Line]:
        """Empty left and right lines whose history covers the config's time at `fps`."""
        timed = self.config.at_rate(self.fps)
        return Line(timed.history, timed.max_misses), Line(timed.history, timed.max_misses)

    def _fresh_history(self) -> tuple[Line, Line, RoadMotion]:
        """Empty lines and road motion whose lengths cover the config's time at `fps`."""
        return *self._fresh_lines(), RoadMotion(self.config.at_rate(self.fps).motion_smoothing)

    def _fresh_dashes(self) -> tuple[DashTrack, DashTrack]:
        """No dashes followed on either side."""
        return DashTrack(self.config.dash_near), DashTrack(self.config.dash_near)

    def reset(self, fps: float | None = None) -> None:
        """Forget both lines' history, their dashes and the road's motion; with `fps`, frames
        now come at that rate (the history keeps covering the same time)."""
        if fps is not None:
            self.fps = fps
        self.left, self.right, self.motion = self._fresh_history()
        self.dashes = self._fresh_dashes()
        self.sides = None

    def view(
        self,
        frame_size: tuple[int, int],
        horizon_y: float | None = None,
        live: tuple[int, int, int, int] | None = None,
        scale_height: float | None = None,
        vanishing_x: float | None = None,
        ground_scale: float = 1.0,
    ) -> BirdsEye:
        """The bird's-eye warp for this frame size and scene (the config's horizon, the whole
        frame and its height when not given; the live centre's column for the vanishing point;
        the tuned camera's ground scale), kept while they stay the same (the app passes a scene
        that moves in steps): a new warp starts the lines' history afresh, and the road's
        motion from a new view (its advances so far stand)."""
        current = self._view
        if (
            current is not None
            and current.frame_size == frame_size
            and horizon_y in (None, current.horizon_y)
            and live in (None, current.live)
            and scale_height in (None, current.scale_height)
            and vanishing_x == current.vanishing_x
            and ground_scale == current.ground_scale
        ):
            return current
        self._view = birdseye_for(
            frame_size, self.config, horizon_y, live, scale_height, vanishing_x, ground_scale
        )
        if current is not None:  # the lines start afresh; the car drives on as fast
            self.left, self.right = self._fresh_lines()
            self.dashes = self._fresh_dashes()  # placed in the old view's metres
            self.motion.new_view()
            if self.sides is not None:
                self.sides.new_view()
        return self._view

    @property
    def current_view(self) -> BirdsEye | None:
        """The warp of the last frame."""
        return self._view

    def process(
        self,
        frame: NDArray[np.uint8],
        horizon_y: float | None = None,
        live: tuple[int, int, int, int] | None = None,
        scale_height: float | None = None,
        vanishing_x: float | None = None,
        overlays: Boxes = (),
        ground_scale: float = 1.0,
        vehicles: NDArray[np.float64] | None = None,
        width_known: bool = True,
        road_x: float | None = None,
        read_turn: bool = False,
    ) -> LaneResult:
        """Find the lane in one undistorted RGB frame and update the history (the warp placed
        from the scene's `horizon_y`, `live` box, `scale_height`, `vanishing_x` and
        `ground_scale` when given); the road's motion is read around the boxes of `vehicles`
        (n, 4: the latest found), the `overlays` and the view's part outside the live picture.
        Without `width_known` (an unknown camera whose lanes' width in pixels was not measured
        yet) a side is not made up at the standard width: one side alone is no lane.
        Paint is read through burnt-in `overlays`: a half-transparent caption leaves the paint
        under it visible, and the paint mask's opening along the road drops its letters (hiding
        the captions' boxes lost the night clip's lane in 3 % of its frames).
        `road_x` is the column of the road's vanishing point as the scene reads it now (the
        view is placed by it only in steps): the camera's place in the lane is read along the
        road it gives; None: along the view's upright. With `read_turn` the road's motion is
        read on the view's two sides too, for the turn it implies (`LaneResult.road_turn_deg`;
        it costs a few milliseconds a frame, so only while a picture's turn is being read)."""
        cfg = self.config
        view = self.view(
            (frame.shape[1], frame.shape[0]),
            horizon_y,
            live,
            scale_height,
            vanishing_x,
            ground_scale,
        )
        bw = view.size[0]
        birdseye = view.warp(frame)
        still = self._still(view, vehicles, overlays)
        advance = self.motion.update(birdseye, view.ym_per_px, still)
        road_turn = self._road_turn(birdseye, view, still) if read_turn else None
        if not read_turn:
            self.sides = None
        lab = lab_picture(birdseye)
        mask = lane_mask(birdseye, cfg, view.xm_per_px, view.ym_per_px, lab)
        paint = Paint.of(mask)
        hints = (cfg.dst_left_x * bw, cfg.dst_right_x * bw)
        pixels = [
            self._find(paint, line, hint, view)
            for line, hint in zip((self.left, self.right), hints, strict=True)
        ]
        lane, sample, believed, status = self._lane_of(pixels, paint, view, width_known, road_x)
        crossing_m = crossing_length(lab[:, :, 0], cfg, view.xm_per_px, view.ym_per_px)
        if crossing_m >= cfg.crossing_min_m:
            # The lines' fits may bend along the bars' ends: no lane is drawn, and the lanes'
            # width is not sampled. Their history goes on (dropped, the lines were then found
            # afresh on the kerbs of India's junction beyond its crossing).
            crossing = f"a pedestrian crossing ahead (its bars over {crossing_m:.1f} m of road)"
            lane, sample, believed = None, None, False
            status = (*status, f"no lane: {crossing}")
        debug = None
        if self.keep_debug:
            bars = None
            if crossing_m >= cfg.crossing_min_m:
                bars = crossing_bars(lab[:, :, 0], cfg, view.xm_per_px, view.ym_per_px)
            debug = LaneDebug(birdseye, mask, pixels[0], pixels[1], bars)
        spacings = self._dash_spacings(paint.mask, lane, view, advance)
        return LaneResult(lane, debug, status, advance, sample, believed, spacings, road_turn)

    def _road_turn(
        self, birdseye: NDArray[np.uint8], view: BirdsEye, still: NDArray[np.bool_]
    ) -> float | None:
        """The turn the road's advance on the view's two sides reads this frame (see
        `SideMotion`), or None until both sides' advances are measured."""
        if self.sides is None:
            self.sides = SideMotion(self.config.at_rate(self.fps).motion_smoothing)
        advances = self.sides.update(birdseye, view.ym_per_px, still)
        if advances is None:
            return None
        left, right = self.sides.columns(view.size[0])
        slopes = (
            view.ray_slope((left.start + left.stop) / 2),
            view.ray_slope((right.start + right.stop) / 2),
        )
        return turn_from_advances(advances, slopes)

    def _lane_of(
        self,
        pixels: list[LinePixels],
        paint: Paint,
        view: BirdsEye,
        width_known: bool,
        road_x: float | None,
    ) -> tuple[LaneEstimate | None, float | None, bool, tuple[str, ...]]:
        """Fit the lines to this frame's `pixels`, check them and update the history; the lane
        the history gives (or None), the width sample, whether it is believed, and the notes
        of what failed (see `process`)."""
        cfg = self.config
        bh = view.size[1]
        enough = [len(p) >= view.pixels_for(cfg.min_line_paint_m2) for p in pixels]
        fits: list[Fit | None]
        bend = self._max_bend(view)
        if all(enough):
            outlier = cfg.outlier_m / view.xm_per_px
            fits = list(fit_lane(pixels[0], pixels[1], bh, outlier, self._prior(bh), bend))
        else:
            fits = [fit_line(p, bend) if ok else None for p, ok in zip(pixels, enough, strict=True)]
        sample, two_lanes = self._width_sample(fits, paint.mask, view)
        status = self._check_and_update(fits, pixels, view)
        slant = 0.0 if road_x is None else view.slant_to(road_x)
        inside, astride = self._line_inside(paint, view, slant)
        if inside is not None:
            status = (*status, inside)
        believed = (
            sample is not None
            and not two_lanes
            and self.left.misses == 0
            and self.right.misses == 0
        )
        lane, doubt = (
            self._estimate(view, width_known, paint.mask, slant)
            if astride is None
            else (None, astride)
        )
        if doubt is not None:
            status = (*status, f"no lane: {doubt}")
        return lane, sample, believed, status

    def _dash_spacings(
        self,
        mask: NDArray[np.uint8],
        lane: LaneEstimate | None,
        view: BirdsEye,
        advance_m: float | None,
    ) -> tuple[float, ...]:
        """The spacings of the dashes along the lane's dashed lines (as believed: paint in
        `dash_share` of the rows along them) that the road's motion completed this frame, in
        the view's metres (see `DashTrack`)."""
        cfg = self.config
        ends = [np.zeros(0), np.zeros(0)]  # none where a line is not dashed, or no lane
        if lane is not None:
            rows = np.arange(view.size[1], dtype=np.float64)
            columns = np.stack([evaluate_fit(fit, rows) for fit in (lane.left_fit, lane.right_fit)])
            half_width = view.columns_for(cfg.dash_half_width_m)
            for side, painted in enumerate(painted_along(mask, columns, half_width)):
                if cfg.dash_share[0] <= painted.mean() <= cfg.dash_share[1]:
                    ends[side] = near_ends(
                        painted, view.ym_per_px, cfg.dash_bridge_m, cfg.dash_length_m
                    )
        found: list[float] = []
        for side_ends, track in zip(ends, self.dashes, strict=True):
            found += track.update(side_ends, view.size[1], view.ym_per_px, advance_m)
        return tuple(found)

    @staticmethod
    def _still(
        view: BirdsEye, vehicles: NDArray[np.float64] | None, overlays: Boxes
    ) -> NDArray[np.bool_]:
        """The bird's-eye pixels that do not move with the road, which the road's motion is read
        around: the view outside the live picture (black), burnt-in captions, and `vehicles`
        (one beside us at our speed stays put). Each pulls the correlation to no motion: a
        faint asphalt's shift was read a ninth of the truth beside the black corners of a view
        sheared to an off-centre vanishing point."""
        still = view.outside
        for boxes in (vehicles, overlays):
            if boxes is not None and len(boxes):
                covered = view.covered(np.asarray(boxes, np.float64).reshape(-1, 4))
                if covered is not None:
                    still = still | covered
        return still

    def _width_sample(
        self, fits: list[Fit | None], mask: NDArray[np.uint8], view: BirdsEye
    ) -> tuple[float | None, bool]:
        """This frame's lane width against the tuned camera's (see `LaneResult.width_sample`):
        the two lines' distance at the nearest row over the lane's columns in the view, times
        the view's ground scale; half of it when a line runs midway between them (two lanes),
        and whether it is such a half. None unless both lines were fitted and run parallel
        (within `sample_parallel`)."""
        cfg = self.config
        left, right = fits
        if left is None or right is None:
            return None, False
        bw, bh = view.size
        widths = lane_widths(left, right, np.array([0.0, bh / 2, float(bh)]))
        if widths.min() <= 0 or widths.max() > (1 + cfg.sample_parallel) * widths.min():
            return None, False
        sample = float(widths[-1] / ((cfg.dst_right_x - cfg.dst_left_x) * bw))
        half_width = view.columns_for(cfg.line_width_m)
        share, coverage = paint_between(mask, left, right, MIDDLE_SHARES, half_width)
        if coverage >= cfg.middle_line_rows:
            if not MIDDLE[0] <= share <= MIDDLE[1]:
                return None, False  # a line well off the middle: which lane is unclear
            return sample / 2 * view.ground_scale, True
        return sample * view.ground_scale, False

    def _line_inside(
        self, paint: Paint, view: BirdsEye, slant: float
    ) -> tuple[str | None, str | None]:
        """Where a lane line runs inside the lane the lines' history gives (a side made up at
        the standard width, or lines more than `one_lane_max_m` apart; in a narrower lane a
        solid line, `solid_line_rows`) and the camera is at least `astride_m` from it, that
        line bounds our lane: it takes the place of the line beyond it in that side's history
        (a thin dashed line has too little paint for a side of its own, and the side was made
        up across it; a kerb or fence was taken for a side beyond a solid edge line). A note
        of it, or None; and why there is no lane where the camera is astride a solid line
        inside a narrow one (one of its sides is no lane line) or astride a line inside one
        with a side made up (which lane is ours the made-up side cannot say), or None. The
        road slants by `slant` columns a row in the view (see `camera_from`)."""
        cfg = self.config
        bh = view.size[1]
        lines = self._history_lane(view)
        if lines is None:
            return None, None
        left, right, made_up = lines
        width_m = float(lane_widths(left, right, np.array([float(bh)]))[0] * view.xm_per_px)
        narrow = not made_up and width_m <= cfg.one_lane_max_m
        half_width = view.columns_for(cfg.line_width_m)
        share, coverage = paint_between(paint.mask, left, right, MIDDLE_SHARES, half_width)
        if coverage < (cfg.solid_line_rows if narrow else cfg.middle_line_rows):
            return None, None
        curve = left + share * (right - left)
        apart_m = camera_from(curve, bh, view.camera_point, slant, view.xm_per_px, view.ym_per_px)
        if abs(apart_m) < cfg.astride_m:
            if narrow:
                return None, f"astride a solid line inside a {width_m:.1f} m lane"
            if made_up:
                return None, "astride a line inside it, one of its sides made up"
            return None, None
        margin = max(1, int(cfg.prior_margin_m / view.xm_per_px))
        fit = fit_line(prior_search(paint, curve, margin), self._max_bend(view))
        if fit is None:
            return None, None
        side = "right" if apart_m < 0 else "left"  # the camera left of the line: our right side
        beyond = self.right if apart_m < 0 else self.left
        beyond.reset()
        beyond.accept(fit)
        return f"{side}: the line inside the lane, {share:.2f} of its {width_m:.1f} m", None

    def _max_bend(self, view: BirdsEye) -> float:
        """The largest y^2 term of a line's fit in `view`'s pixels that a road bends by at our
        speed (the road's motion; `max_sideways_mps2`), inf while the speed is unknown or so
        low that `min_radius_m` bounds the bend: x = a y^2 bends by 1 / (2 a) metres once both
        axes are in metres."""
        cfg = self.config
        advance = self.motion.advance
        if advance is None:
            return np.inf
        speed = abs(advance) * (self.fps if self.fps > 0 else cfg.frame_rate)
        radius = speed**2 / cfg.max_sideways_mps2
        if radius <= cfg.min_radius_m:
            return np.inf
        return view.ym_per_px**2 / (2 * view.xm_per_px * radius)

    def _prior(self, rows: int) -> LanePrior | None:
        """Heading and near width of the smoothed lane, if both lines have history."""
        left, right = self.left.smoothed, self.right.smoothed
        if left is None or right is None:
            return None
        return LanePrior(
            heading=float(np.mean([2 * f[0] * rows + f[1] for f in (left, right)])),
            near_width=float(evaluate_fit(right, rows) - evaluate_fit(left, rows)),
            heading_weight=self.config.heading_prior,
            near_width_weight=self.config.near_width_prior,
        )

    def _find(self, paint: Paint, line: Line, hint: float, view: BirdsEye) -> LinePixels:
        cfg = self.config
        bh = view.size[1]
        prior = line.smoothed
        if line.trusted and prior is not None:
            found = prior_search(paint, prior, int(cfg.prior_margin_m / view.xm_per_px))
            if len(found) >= view.pixels_for(cfg.min_line_paint_m2):
                return found
        if prior is not None:
            hint = float(evaluate_fit(prior, bh))
        spread = 0.35 * (cfg.dst_right_x - cfg.dst_left_x) * view.size[0]
        side_hint = histogram_base(paint.mask, hint, spread)
        return window_search(
            paint,
            side_hint,
            cfg.windows,
            int(cfg.window_margin_m / view.xm_per_px),
            view.pixels_for(cfg.min_window_paint_m2),
        )

    def _check_and_update(
        self, fits: list[Fit | None], pixels: list[LinePixels], view: BirdsEye
    ) -> tuple[str, ...]:
        """Sanity checks; accept or reject each line's new fit. Returns notes of what failed."""
        cfg = self.config
        bh = view.size[1]
        rows = np.array([0.0, bh / 2, float(bh)])
        notes: list[str] = []
        lines = (self.left, self.right)
        ok = [f is not None for f in fits]
        turned: int | None = None  # a line turning off the lane (see `_turned_off`)
        for i, (fit, line) in enumerate(zip(fits, lines, strict=True)):
            if fit is None:
                notes.append(f"{('left', 'right')[i]}: too few pixels ({len(pixels[i])})")
                continue
            prior = line.smoothed
            if prior is not None:
                jump = np.abs(evaluate_fit(fit, rows) - evaluate_fit(prior, rows)).max()
                if jump * view.xm_per_px > cfg.max_jump_m * (1 + line.misses):
                    ok[i] = False
                    notes.append(f"{('left', 'right')[i]}: jumped {jump * view.xm_per_px:.2f} m")
        if ok[0] and ok[1]:
            assert fits[0] is not None and fits[1] is not None
            doubt = implausible_lane(
                fits[0],
                fits[1],
                rows,
                view.xm_per_px,
                view.ym_per_px,
                (cfg.min_lane_width_m, cfg.max_lane_width_m),
                cfg.max_width_change_m,
                0.0,  # a bend is judged on the smoothed lane (`_estimate`)
            )
            if doubt is not None:
                notes.append(doubt)
                # Keep the line with history, else the one backed by more paint; but of two
                # with history, one turning off the lane ahead is dropped (an edge line along
                # an exit: the lane's dashes go on; see `_turned_off`).
                known = [line.smoothed is not None for line in lines]
                if known[0] != known[1]:
                    ok[known.index(False)] = False
                elif known[0] and (turned := self._turned_off(fits, view)) is not None:
                    ok[turned] = False
                else:
                    ok[int(len(pixels[0]) > len(pixels[1]))] = False
        for i, (fit, line, good) in enumerate(zip(fits, lines, ok, strict=True)):
            if good and fit is not None:
                line.accept(fit)
            else:
                line.reject(turning_off=i == turned)
        return tuple(notes)

    def _turned_off(self, fits: list[Fit | None], view: BirdsEye) -> int | None:
        """Which line (0 left, 1 right) of a lane whose new fits part ahead turns off it; None
        when no one line does. The fits are one lane apart at the near row (2.6-4.6 m, to
        `one_lane_max_m`) and wider at the far one, and one line's far end moved out (away from
        the other) from its own history while the other's did not, that line followed up to now
        (a line lost for a frame or more and found farther out has moved for another reason:
        the Indian clip's edge line at 1.5 s); or a line already turning off moved out farther
        than the other (whose history, kept while its fits were rejected, falls behind too)."""
        cfg = self.config
        left, right = fits
        assert left is not None and right is not None
        far, near = lane_widths(left, right, np.array([0.0, float(view.size[1])]))
        if not cfg.min_lane_width_m <= near * view.xm_per_px <= cfg.one_lane_max_m or far <= near:
            return None
        lines = (self.left, self.right)
        out = []  # each far end's move out (row 0: x is the fit's constant term)
        for sign, fit, line in zip((-1.0, 1.0), (left, right), lines, strict=True):
            assert line.smoothed is not None
            out.append(sign * float(fit[-1] - line.smoothed[-1]))
        moving = int(out[1] > out[0])
        line = lines[moving]
        if line.turning_off:
            return moving if out[moving] > 0 else None
        return moving if out[1 - moving] <= 0 < out[moving] and line.misses == 0 else None

    def _history_lane(self, view: BirdsEye) -> tuple[Fit, Fit, bool] | None:
        """Both lines' smoothed fits, a side without history following the other at the
        standard lane width, and whether one did; None when neither has history."""
        cfg = self.config
        left, right = self.left.smoothed, self.right.smoothed
        if left is None and right is None:
            return None
        lane_px = (cfg.dst_right_x - cfg.dst_left_x) * view.size[0]
        made_up = left is None or right is None
        if left is None:
            assert right is not None
            left = right - np.array([0.0, 0.0, lane_px])
        if right is None:
            right = left + np.array([0.0, 0.0, lane_px])
        return left, right, made_up

    def _estimate(
        self, view: BirdsEye, width_known: bool, mask: NDArray[np.uint8], slant: float
    ) -> tuple[LaneEstimate | None, str | None]:
        """The lane from the lines' history, or None and why when it is not one a road can have
        (too narrow or wide, not parallel, too sharp a bend, painted across), not ours (the
        camera outside it: the lines' history is then dropped, so the next frame searches near
        the car) or has a side made up at a width not `width_known`: no lane rather than a
        wrong one. The road slants by `slant` columns a row in the view (see `camera_from`)."""
        cfg = self.config
        bw, bh = view.size
        lines = self._history_lane(view)
        if lines is None:
            return None, None
        left, right, made_up = lines
        if made_up and not width_known:
            return None, "one side alone, and the lanes' width on this camera not measured yet"
        doubt = implausible_lane(
            left,
            right,
            np.array([0.0, bh / 2, float(bh)]),
            view.xm_per_px,
            view.ym_per_px,
            (cfg.min_lane_width_m, cfg.max_lane_width_m),
            cfg.max_width_change_m,
            cfg.min_radius_m,
            cfg.max_heading_deg,
        )
        if doubt is not None:
            return None, doubt
        # Paint along a line inside the lane (the astride rule's) is not paint across it.
        half_width = view.columns_for(cfg.line_width_m)
        share, coverage = paint_between(mask, left, right, ALONG_SHARES, half_width)
        along = left + share * (right - left) if coverage >= cfg.middle_line_rows else None
        margin = cfg.inside_margin_m / view.xm_per_px
        painted = paint_inside(mask, left, right, margin, view.outside, along)
        if painted > cfg.max_inside_paint:
            return None, f"paint across it ({painted:.0%} of it: a crossing)"
        # From the live picture's bottom up to the trapezoid's top row (where the warp is sure).
        lx0, _, lx1, ly1 = view.live
        middle = (lx0 + lx1) / 2
        top = float(view.to_frame(np.array([[bw / 2, 0.0]]))[0, 1])
        frame_rows = np.linspace(ly1 - 1, top, cfg.polyline_points)
        bird_rows = view.to_birdseye(np.stack([np.full_like(frame_rows, middle), frame_rows], 1))
        bird_rows = bird_rows[:, 1]
        polylines = []
        for fit in (left, right):
            pts = np.stack([evaluate_fit(fit, bird_rows), bird_rows], axis=1)
            polylines.append(view.to_frame(pts))
        radius, offset, width = lane_figures(left, right, view, slant, cfg.straight_radius_m)
        # Outside once past the line's paint (its fit is the paint's middle): over it, the
        # camera is still on the lane's edge.
        if abs(offset) > cfg.max_offset_share * width + cfg.line_width_m / 2:
            self.left.reset()
            self.right.reset()
            return (
                None,
                f"the camera is outside it ({offset:+.2f} m off the centre of {width:.2f} m)",
            )
        return LaneEstimate(polylines[0], polylines[1], radius, offset, left, right, width), None
