"""Every parameter of the vehicle detector; sizes are fractions of the frame so any size works."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np


@dataclass(frozen=True)
class Band:
    """A horizontal band searched with one square window size (fractions of frame height/width)."""

    window: float  # window side / frame height
    top: float  # band top / frame height
    bottom: float  # band bottom / frame height
    left: float = 0.0  # band left / frame width
    right: float = 1.0
    step_cells: int = 1  # window step in HOG cells
    # Not searched where its window would be smaller than this many pixels: a car that small has
    # too few pixels for the classifier's 8-pixel cells, whatever its share of the picture.
    min_window_px: float = 0.0
    # A hit whose centre lies in a hit of windows at least this many times larger is a part of
    # that vehicle (a small window fires on a near car's tail light) and does not heat; None: off.
    part_ratio: float | None = None
    # The patch size of the model that searches the band: the smallest windows are read by a
    # 32 px model, a quarter of the pixels to compute (a band without its model is not searched).
    patch: int = 64


def _default_bands() -> tuple[Band, ...]:
    # At 1280x720: 40, 64, 96, 128 and 192 px windows, and 24 px last (the interleaved halves are
    # every other band: three and three); small ones near the horizon (y ~ 420). The 40 and 24 px
    # bands cover the left three quarters: small vehicles there are far ahead or oncoming over the
    # median, while on the right they are close and large. The larger bands reach half a window
    # past the frame's sides (mirrored) so a vehicle entering the frame is found.
    return (
        Band(window=40 / 720, top=400 / 720, bottom=472 / 720, left=0.0, right=0.75),
        Band(window=64 / 720, top=392 / 720, bottom=496 / 720),
        Band(window=96 / 720, top=388 / 720, bottom=548 / 720, left=-0.04, right=1.04),
        Band(window=128 / 720, top=384 / 720, bottom=592 / 720, left=-0.05, right=1.05),
        Band(window=192 / 720, top=380 / 720, bottom=668 / 720, left=-0.08, right=1.08),
        # Cars 3-4 % of the height, far ahead or oncoming, where a 24 px window still has 11 px
        # (from 360 rows: the night clip, where 12 px windows once boxed dark road, has no box).
        Band(
            window=24 / 720,
            top=408 / 720,
            bottom=452 / 720,
            right=0.75,
            min_window_px=11.0,
            part_ratio=2.0,
            patch=32,
        ),
    )


@dataclass(frozen=True)
class HeatConfig:
    """How the `Heatmap` accumulates window hits and turns them into regions."""

    history: int = 8  # frames combined
    threshold: float = 2.5  # mean heat per frame over the history a pixel must exceed
    scale: int = 4  # the heat map is kept at 1/scale of the frame size
    recent: int = 2  # newest frames that place each vehicle (both interleaved band sets)
    recent_threshold: float = 1.0  # mean heat per frame over those a vehicle's pixels must exceed
    peak_fraction: float = 0.35  # a region's box keeps heat above this fraction of its peak
    # A region at the frame's left or right side: its width is taken at this fraction of its peak
    # (mirrored windows past the side pile heat up there); None: as any other region.
    edge_peak_fraction: float | None = 0.2
    split_valley: float = 0.6  # two peaks split a region when the valley is below this x peak


@dataclass(frozen=True)
class TrackConfig:
    """How the `Tracker` matches, smooths, shows and drops tracks."""

    match_iou: float = 0.2
    smoothing: float = 0.5  # weight of the measured box against the predicted one
    velocity_gain: float = 0.3  # how much of the prediction error corrects a track's velocity
    min_inside: float = 0.9  # a track whose box is less than this share in the frame is dropped
    confirm_frames: int = 4  # a track is shown once seen in this many frames
    max_missed: int = 8  # a track is dropped after this many frames unseen
    show_missed: int = 4  # a confirmed track stays shown through this many missed frames
    # A shown vehicle unseen longer than `max_missed` (not gone from the picture; or still shown
    # and its box run past the picture's side: for `max_missed` frames) keeps its id for a
    # vehicle found within this many frames of its last sighting where it could be: along
    # its last motion up to `rejoin_reach` times as far, a box there and the found one
    # overlapping by `rejoin_overlap` of the smaller one, their areas within `rejoin_area`
    # times each other (see `Tracker`).
    forget_missed: int = 25
    rejoin_reach: float = 2.0
    rejoin_overlap: float = 0.5
    rejoin_area: float = 4.0
    # A box's side leaving the picture's edge is a vehicle coming in if its motion brought it
    # that far within this many frames (more: heat falling short of a vehicle still cut).
    entering_frames: int = 6


@dataclass(frozen=True)
class DetectorConfig:
    """Search bands, heat and tracking settings (defaults for 25 fps video)."""

    bands: tuple[Band, ...] = field(default_factory=_default_bands)
    # The bands were placed for the horizon at this fraction of the height (the shipped camera's
    # 420.8 of 720 rows); with another horizon they move with it.
    reference_horizon: float = 420.8 / 720
    # Pictures under this many rows (the view's scale height) are read by the low-resolution
    # model, when there is one, instead of the model: at such sizes a window sees the footage's
    # colour at half resolution and its compression blocks at its own scale (at 720 rows it is
    # mostly shrunk twofold or more, which averages them away), and the model, trained on sharp
    # crops, misses cars there (see the README).
    lowres_rows: float = 540.0
    min_probability: float = 0.9  # a window adds heat when the calibrated P(vehicle) is above
    # ... or this much on a road at dusk (a car there has a third of its daylight contrast and
    # the model, calibrated on daylight crops, is less sure of it): `dark_min_probability` where
    # the road ahead's grey level is from `dark_road[1]` to `dark_road[2]`, `min_probability`
    # from `dark_road[3]` up and, on a road darker than `dark_road[0]` (night, where the
    # encoder's noise is most of what there is), down; linearly between.
    dark_min_probability: float = 0.7
    dark_road: tuple[float, float, float, float] = (10.0, 20.0, 40.0, 60.0)
    # In monochrome pictures, read by the grey models (97.0 % grouped accuracy against the
    # colour model's 98.9 %), a window heats from this P(vehicle) in any light: on grey copies
    # of the shared clips 0.9 kept 63 false boxes against 158 cars, 0.98 4 against 145
    # (0.99: 18 against 128; README, Monochrome footage).
    monochrome_min_probability: float = 0.98
    # On a road darker than `dark_road[2]` (dusk, night) the windows read the mean of the last
    # `dark_frames` frames: the encoder renders a dim sensor's grain anew in every frame, while a
    # car ahead stays where it was (the grainy copies' false boxes, README); 1: the frame alone.
    # From `very_grainy` the mean of `grainy_dark_frames`: on copies of the shared clips dimmed
    # to a black road (grain read 0.1-0.4) 2 frames keep 455 cars and 21 false boxes against
    # 434 / 31 with 3 (each with its dark verifier), on those dimmed to dusk with grain 2.4
    # 163 / 7 against 160 / 0 (README).
    dark_frames: int = 2
    grainy_dark_frames: int = 3
    # ... and of `grain_frames` where the grain reaches `dark_grain` too: copies dimmed to dusk
    # with grain 4-8 kept 28 false boxes over four draws with 3 frames, 1 with 5 (and 1.7 %
    # fewer cars); with 5 from grain 1, those with grain 2.4 lost 5 cars and gained 4 false
    # boxes (README).
    dark_grain: float = 4.0
    # Where the road's grain (`camera_cal.scene.grain`) is at least `grainy` grey levels, in
    # any light, the windows read the picture with its colour smoothed (a Gaussian on the
    # chroma channels, the lightness kept, of `chroma_sigma` of the scale height: 2 px at 720
    # rows; 2 px at 360 rows cost cars, at 1080 left false boxes; README): HOG stretches every
    # block to full strength, and a flat road's chroma, where the sensor's grain is all there is
    # to stretch, reads as a car's coloured edges (test1.jpg given chroma noise of 2 grey levels:
    # 1,306 windows sure of a car against 52; lightness noise of 6: 32). The shared and wild
    # clips read 0.35 at most, copies with half the grain 0.45. From `very_grainy` the windows
    # also read the mean of the last `grain_frames` frames: copies of the shared clips with
    # grain of 0.6-0.7 keep more cars without it (166 against 151), those of 1.2 and more keep
    # false boxes (36 against 3; README). At dusk too: copies dimmed with grain of 2 kept 446
    # false boxes without the smoothing, none with it (README). From `chroma_grain` the
    # Gaussian widens by the square root of the grain over it: copies with grain 5.7, 7.2 and
    # 9.8 kept 30, 123 and 274 false boxes at 2 px, 0, 0 and 4 so (in proportion to the grain,
    # 3.6 px at 7.2, cars were lost: 147 against 159; README).
    grainy: float = 0.5
    chroma_sigma: float = 2.0 / 720
    chroma_grain: float = 4.0
    very_grainy: float = 1.0
    grain_frames: int = 5
    # ... and, with a verifier (a model that also learned hard negatives: dark road, wet road,
    # verges, paint at night), when the verifier's P(vehicle) is at least this: it vetoes what
    # fooled the detector, while the detector's windows still place the boxes. On a dark road
    # the dark verifier, when there is one, checks them instead (see `VehicleDetector`).
    min_verified: float = 0.3
    # ... and where the model's P(vehicle) of the window's mirror image is at least this, or
    # the window's centre lies in one whose is (None: not checked). A vehicle's rear is nearly
    # symmetric, and seen from its side its mirror image is a vehicle facing the other way; a
    # roadside's texture has no such symmetry. The training set's non-vehicles hold crops of the
    # project video's median barrier on the left, so the model knows that barrier there and not
    # on the right, where it stands where traffic keeps left (or a rear camera sees it): read
    # mirrored, it is known again. The shared clips mirrored and not told so: precision 0.936 ->
    # 1.000; at 0.9 (a window and its mirror image alike, in every band) the clips as they are
    # lost precision, 1.000 -> 0.965 (README).
    min_mirrored: float | None = 0.5
    # ... in the bands whose windows are at least this share of the height (96 px at 720 rows):
    # in smaller ones a car has few pixels for its mirror image to read as one (on the shared
    # clips' cars 15-23 % of the sure windows' mirror images fail, against 7-11 % from 96 px),
    # and a far car is held by a window or two a frame, so a veto there loses it.
    mirrored_from: float = 96 / 720
    # A window does not heat where burnt-in captions (a timestamp, a watermark) cover at least
    # this share of it: their letters' edges are no car's.
    max_overlay: float = 0.25
    # The part of each hit's window that is heated, (x0, y0, x1, y1) as fractions of its size:
    # training crops are wider than the car is tall, with road showing below it.
    heat_footprint: tuple[float, float, float, float] = (0.0, 0.1, 1.0, 0.85)
    # A box's bottom moves to where the picture brightens most going down (shadow and tyres give
    # way to road), searched this share of its height above and below it (None: heat alone), if
    # the rise is at least `bottom_min_rise` grey levels (see vehicles/refine.py).
    bottom_reach: tuple[float, float] | None = (0.3, 0.3)
    bottom_min_rise: float = 8.0
    # A box's top moves to where the picture changes most across its middle (the roof's outline),
    # searched this share of its height above and below it (None: heat alone), if the change is
    # at least `top_min_change` grey levels: heat from square windows on a car about half as tall
    # as wide reaches above its roof. Less far up, where other cars, barriers and bridges have
    # edges as strong (see vehicles/refine.py).
    top_reach: tuple[float, float] | None = (0.1, 0.2)
    top_min_change: float = 20.0
    # A box reaches this share of its width further towards the road's vanishing column: a car
    # beside the camera's axis shows its rear (or front) and the side that faces the axis, and
    # the windows, trained mostly on rear views, heat the end and stop short of that side; a car
    # whose box moves more than `fast_share` of its width a frame (oncoming traffic) reaches half
    # its motion the way it moves instead, as its heat trails it (see vehicles/refine.py).
    side_reach: float = 0.08
    fast_share: float = 0.12
    min_box: float = 0.025  # smallest box side reported / frame height
    # Video frames alternate between two halves of the bands (the heat history spans both).
    interleave: bool = True
    heat: HeatConfig = field(default_factory=HeatConfig)
    track: TrackConfig = field(default_factory=TrackConfig)
    # The frame rate the frame counts of `heat` and `track` are for: at another rate they cover
    # the same time (`at_rate`), so a car is shown, kept and dropped after as many seconds.
    frame_rate: float = 25.0

    def is_dark(self, road_grey: float | None) -> bool:
        """Whether a road ahead of this grey level (None: unknown, taken as daylight) is at dusk
        or darker (under `dark_road[2]`): the windows read the mean of the last frames and the
        dark verifier checks them."""
        return road_grey is not None and road_grey < self.dark_road[2]

    def averaged_frames(self, road_grey: float | None, grain: float | None) -> int:
        """How many of the last frames the windows read the mean of: on a dark road
        (`is_dark`) `dark_frames`, `grainy_dark_frames` where the grain reaches `very_grainy`,
        `grain_frames` where it reaches `dark_grain`; else `grain_frames` on a very grainy road
        (`very_grainy`), else 1."""
        noise = 0.0 if grain is None else grain  # unknown: read as none
        if self.is_dark(road_grey) and noise < self.dark_grain:
            return self.grainy_dark_frames if noise >= self.very_grainy else self.dark_frames
        return self.grain_frames if noise >= self.very_grainy else 1

    def chroma_sigma_at(self, grain: float | None, rows: float) -> float | None:
        """The Gaussian (px) that smooths the picture's colour on a road of this `grain` (from
        `grainy`, at any light; None under it or unknown: the colour is read as it is), in a
        picture of `rows` scale height: `chroma_sigma` of the rows, widened by the square root
        of the grain over `chroma_grain` beyond it."""
        if grain is None or grain < self.grainy:
            return None
        return float(self.chroma_sigma * rows * np.sqrt(max(1.0, grain / self.chroma_grain)))

    def mirror_checks(self, band: Band) -> bool:
        """Whether the windows of `band` must stand by their mirror image (`min_mirrored`)."""
        return self.min_mirrored is not None and band.window >= self.mirrored_from - 1e-9

    def min_probability_at(self, road_grey: float | None, monochrome: bool = False) -> float:
        """The least P(vehicle) of a hit on a road ahead of this grey level (None: unknown,
        taken as daylight), in a `monochrome` picture `monochrome_min_probability`."""
        if monochrome:
            return self.monochrome_min_probability
        if road_grey is None:
            return self.min_probability
        day, dusk = self.min_probability, self.dark_min_probability
        return float(np.interp(road_grey, self.dark_road, (day, dusk, dusk, day)))

    def at_rate(self, fps: float) -> DetectorConfig:
        """The same settings for video at `fps` frames a second: the heat history and the
        tracker's counts scaled to cover the same time (at least a frame; `recent` stays two
        frames, one of each interleaved half of the bands), and the tracker's weights to forget
        as much a second (kept per frame, a box following a car that speeds across the picture
        trailed it by twice as many frames' motion at half the rate)."""
        if fps <= 0 or fps == self.frame_rate:
            return self

        def frames(count: int) -> int:
            return max(1, round(count * fps / self.frame_rate))

        def per_second(weight: float) -> float:
            # What is left of the old estimate after a second, (1 - weight) ** fps, is kept:
            # a car's place and motion across the picture change over seconds, not frames.
            return 1.0 - float((1.0 - weight) ** (self.frame_rate / fps))

        heat = replace(self.heat, history=max(self.heat.recent, frames(self.heat.history)))
        track = replace(
            self.track,
            smoothing=per_second(self.track.smoothing),
            velocity_gain=per_second(self.track.velocity_gain),
            confirm_frames=frames(self.track.confirm_frames),
            max_missed=frames(self.track.max_missed),
            show_missed=frames(self.track.show_missed),
            forget_missed=frames(self.track.forget_missed),
            entering_frames=frames(self.track.entering_frames),
        )
        return replace(
            self,
            heat=heat,
            track=track,
            dark_frames=frames(self.dark_frames),
            grainy_dark_frames=frames(self.grainy_dark_frames),
            grain_frames=frames(self.grain_frames),
            frame_rate=fps,
        )

    def for_still(self) -> DetectorConfig:
        """The same search for a single image: every band, no history to wait for or average."""
        return replace(
            self,
            interleave=False,
            dark_frames=1,
            grainy_dark_frames=1,
            grain_frames=1,
            heat=replace(self.heat, history=1),
            track=replace(self.track, confirm_frames=1),
        )
