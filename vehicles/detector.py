"""The vehicle stage: dense multi-scale search, Heatmap history, tracking; one call per frame."""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from vehicles.config import DetectorConfig
from vehicles.detections import Detections, covered_share, smaller_sides
from vehicles.heatmap import Heatmap
from vehicles.model import ModelError, VehicleModel
from vehicles.refine import reach_toward, snap_bottoms, snap_tops
from vehicles.search import BandHits, LinearWeights, View, band_geometry, search_band
from vehicles.tracker import Tracker


@dataclass(frozen=True, eq=False)
class VehicleDebug:
    """Intermediates of one frame for the debug mode."""

    hits: tuple[BandHits, ...]
    frame_heat: NDArray[np.float32]
    history_heat: NDArray[np.float32]
    regions: Detections
    heat_threshold: float
    vetoed: NDArray[np.float64]  # (n, 4) windows the model was sure of, vetoed (verifier, mirror)
    # The picture the windows read, where it is not the frame itself (`VehicleDetector.seen`):
    # the mean of this many of the last frames, and with its colour smoothed or not.
    seen: NDArray[np.uint8] | None = None
    averaged: int = 1
    smoothed: bool = False
    # Vehicles unseen whose ids are kept, where they would be (`Tracker.remembered`).
    remembered: Detections = field(default_factory=Detections)


@dataclass(frozen=True, eq=False)
class Scorer:
    """A model and its optional verifier, with their weights for the dense search."""

    model: VehicleModel
    weights: LinearWeights
    verifier: VehicleModel | None = None
    verifier_weights: LinearWeights | None = None
    mirrored_weights: LinearWeights | None = None  # the model's, of each window's mirror image

    @classmethod
    def of(cls, model: VehicleModel, verifier: VehicleModel | None = None) -> Scorer:
        """The scorer of `model`, checked by `verifier` (trained on the same features)."""
        if verifier is not None and verifier.config != model.config:
            raise ModelError("the verifier was trained on other features than the model")
        weights = LinearWeights.from_model(model)
        return cls(
            model,
            weights,
            verifier,
            None if verifier is None else LinearWeights.from_model(verifier),
            weights.mirrored(),
        )


@dataclass(frozen=True, eq=False)
class VehicleResult:
    """Shown vehicles of one frame (tracked), and optionally the intermediates."""

    detections: Detections
    debug: VehicleDebug | None = field(default=None)


def footprint(
    boxes: NDArray[np.float64], part: tuple[float, float, float, float]
) -> NDArray[np.float64]:
    """The `part` (x0, y0, x1, y1 as fractions of width and height) of each box."""
    size = np.tile(boxes[:, 2:] - boxes[:, :2], 2)
    return np.asarray(np.tile(boxes[:, :2], 2) + size * np.asarray(part))


def parts_of_larger(
    hits: Sequence[BandHits], boxes: NDArray[np.float64], strong: NDArray[np.bool_]
) -> NDArray[np.bool_]:
    """Which of the `strong` windows (`boxes`: every band's windows of `hits`, in order) are a
    part of a larger vehicle: windows of a band with a `part_ratio` whose centre lies in a strong
    window at least that many times larger (a small window fires on a near car's tail light)."""
    sizes = np.concatenate([np.full(len(hit.boxes), hit.window_px) for hit in hits])
    ratios = np.concatenate([np.full(len(hit.boxes), hit.band.part_ratio or 0.0) for hit in hits])
    parts = np.zeros(len(boxes), bool)
    small = np.flatnonzero(strong & (ratios > 0))
    if len(small) == 0:
        return parts
    larger = strong[None, :] & (sizes[None, :] >= (ratios[small] * sizes[small])[:, None])
    parts[small] = (larger & centres_within(boxes[small], boxes)).any(axis=1)
    return parts


def centres_within(boxes: NDArray[np.float64], others: NDArray[np.float64]) -> NDArray[np.bool_]:
    """(n, m): whether the centre of each of `boxes` lies in each of `others` (edges included)."""
    centres = (boxes[:, :2] + boxes[:, 2:]) / 2
    return np.asarray(
        (centres[:, None, 0] >= others[None, :, 0])
        & (centres[:, None, 0] <= others[None, :, 2])
        & (centres[:, None, 1] >= others[None, :, 1])
        & (centres[:, None, 1] <= others[None, :, 3])
    )


def mirror_backed(
    boxes: NDArray[np.float64], symmetric: NDArray[np.bool_], backing: NDArray[np.bool_]
) -> NDArray[np.bool_]:
    """Which windows (`boxes`) stand by their mirror image: those `symmetric` (their mirror
    image reads as a vehicle too), and those whose centre lies in a `backing` window (one sure
    of itself and of its mirror image): a car's corner seen partly from its side is no mirror
    image of itself, its middle is."""
    backed = centres_within(boxes, boxes[backing]).any(axis=1) if backing.any() else False
    return np.asarray(symmetric | backed)


def frame_mean(frames: Sequence[NDArray[np.uint8]]) -> NDArray[np.uint8]:
    """The rounded mean, pixel by pixel, of equally sized uint8 frames."""
    total = np.zeros(frames[0].shape, np.uint16)
    for frame in frames:
        total += frame
    return ((total + len(frames) // 2) // len(frames)).astype(np.uint8)


def gaussian_reach(sigma: float) -> int:
    """How many pixels each side a Gaussian of `sigma` px reads (OpenCV's kernel for 8-bit
    pictures: 3 sigma; 4 taken, and a pixel more)."""
    return int(np.ceil(4 * sigma)) + 1


def chroma_smoothed(frame: NDArray[np.uint8], sigma: float) -> NDArray[np.uint8]:
    """An RGB frame with its chroma (YCrCb's Cr and Cb) blurred by a Gaussian of `sigma` px and
    its lightness kept: a sensor's colour grain smoothed away, a car's shape left sharp."""
    # Channel by channel: blurring a strided view of the channels took twice as long (29 ms
    # against 13.5 at 720p).
    lightness, *chroma = cv2.split(cv2.cvtColor(frame, cv2.COLOR_RGB2YCrCb))
    blurred = [cv2.GaussianBlur(channel, (0, 0), sigma) for channel in chroma]
    return np.asarray(cv2.cvtColor(cv2.merge([lightness, *blurred]), cv2.COLOR_YCrCb2RGB))


def seen_picture(
    frames: Sequence[NDArray[np.uint8]],
    sigma: float | None,
    rows: tuple[int, int] | None = None,
) -> NDArray[np.uint8]:
    """What the windows read of the last of `frames`: the mean of `frames` (`frame_mean`), its
    colour smoothed by a Gaussian of `sigma` px (`chroma_smoothed`; None: as it is), over `rows`
    (top, bottom; None: all) alone and the last frame's own pixels elsewhere. The windows read
    their bands' rows alone: at 720p the mean of 3-5 whole frames took 14-18 ms, of those rows
    3-6, and the smoothing 9.2 ms against 5.0."""
    frame = frames[-1]
    if len(frames) == 1 and sigma is None:
        return frame
    height = frame.shape[0]
    top, bottom = (0, height) if rows is None else rows
    # Read a margin as far as the Gaussian reaches, so the rows come out as over the whole frame.
    reach = 0 if sigma is None else gaussian_reach(sigma)
    start, stop = max(0, top - reach), min(height, bottom + reach)
    part = (
        frame_mean([past[start:stop] for past in frames]) if len(frames) > 1 else frame[start:stop]
    )
    if sigma is not None:
        part = chroma_smoothed(part, sigma)
    if (top, bottom) == (0, height):
        return part
    picture = frame.copy()
    picture[top:bottom] = part[top - start : bottom - start]
    return picture


def checked_by(scorers: dict[int, Scorer], verifier: VehicleModel) -> dict[int, Scorer]:
    """`scorers` with each one whose model reads `verifier`'s features checked by it instead."""
    reads = (patch for patch, scorer in scorers.items() if scorer.model.config == verifier.config)
    return {**scorers, **{patch: Scorer.of(scorers[patch].model, verifier) for patch in reads}}


class VehicleDetector:
    """Finds vehicles in every frame; keeps a Heatmap and a Tracker as history.

    Bands are split into two alternating sets so each frame searches about half of them; the heat
    history spans several frames, so every scale still contributes to every decision.
    """

    def __init__(
        self,
        model: VehicleModel,
        config: DetectorConfig | None = None,
        keep_debug: bool = False,
        verifier: VehicleModel | None = None,
        small: Scorer | None = None,
        lowres: VehicleModel | None = None,
        dark_verifier: VehicleModel | None = None,
        grey: dict[int, Scorer] | None = None,
    ) -> None:
        self.model = model
        self.config = config if config is not None else DetectorConfig()
        # The scorer of each band's patch size (`small`: the smallest windows' model, if any).
        self.scorers = {model.config.patch_size: Scorer.of(model, verifier)}
        if small is not None:
            self.scorers.setdefault(small.model.config.patch_size, small)
        # Pictures of fewer rows than `lowres_rows` are read by `lowres` in its patch size's
        # bands, checked by the same verifier.
        self.lowres_scorers = (
            self.scorers
            if lowres is None
            else {**self.scorers, lowres.config.patch_size: Scorer.of(lowres, verifier)}
        )
        # On a dark road the models whose features `dark_verifier` reads are checked by it
        # instead: it also learned a dim sensor's grain (see `make train`).
        self.dark_scorers, self.dark_lowres_scorers = self.scorers, self.lowres_scorers
        if dark_verifier is not None:
            self.dark_scorers = checked_by(self.scorers, dark_verifier)
            self.dark_lowres_scorers = checked_by(self.lowres_scorers, dark_verifier)
        # Pictures without colour (an infrared night camera's, a grey-only export) are read by
        # `grey`, the scorer of each patch size trained on grey copies of the patches: the
        # colour models find no vehicle there (README, Monochrome footage). Missing: as in colour.
        self.grey_scorers = grey or {}
        self.keep_debug = keep_debug
        self.fps = 0.0  # the video's frame rate; 0: the one the config's counts are for
        self.heatmap, self.tracker, self.recent = self._fresh_history()
        self.frame_index = 0

    def _fresh_history(self) -> tuple[Heatmap, Tracker, deque[NDArray[np.uint8]]]:
        """An empty heat map, tracker and store of recent frames (read averaged on a dark or
        grainy road) whose frame counts cover the config's time at `fps`."""
        timed = self.config.at_rate(self.fps)
        # Region boxes come from heat averaged over the recent frames: centred that far back.
        tracker = Tracker(timed.track, lag=(timed.heat.recent - 1) / 2)
        longest = max(timed.dark_frames, timed.grainy_dark_frames, timed.grain_frames)
        store: deque[NDArray[np.uint8]] = deque(maxlen=longest)
        return Heatmap(timed.heat), tracker, store

    def reset(self, fps: float | None = None) -> None:
        """Forget heat and tracks; with `fps`, frames now come at that rate (the history keeps
        covering the same time)."""
        if fps is not None:
            self.fps = fps
        self.heatmap, self.tracker, self.recent = self._fresh_history()
        self.frame_index = 0

    def seen(
        self,
        frame: NDArray[np.uint8],
        road_grey: float | None,
        grain: float | None = None,
        scale_height: float | None = None,
    ) -> NDArray[np.uint8]:
        """The picture the windows read: on a road at dusk or darker (`road_grey` under
        `DetectorConfig.dark_road[2]`) the mean of the last frames, this one included (as many
        as `DetectorConfig.averaged_frames` says for its `grain`), on a very grainy one (`grain`
        from `DetectorConfig.very_grainy`) of the last `grain_frames`, else the frame itself
        (and the stored frames are forgotten); on a grainy road, in any light, with its colour
        smoothed (`DetectorConfig.chroma_sigma_at`) in proportion to `scale_height`
        (`View.scale_height`; None: the frame's height)."""
        return self._read(frame, road_grey, grain, scale_height)[0]

    def _read(
        self,
        frame: NDArray[np.uint8],
        road_grey: float | None,
        grain: float | None,
        scale_height: float | None,
        rows: tuple[int, int] | None = None,
    ) -> tuple[NDArray[np.uint8], int, bool]:
        """`seen`'s picture (averaged and its colour smoothed over `rows` alone when given), how
        many frames it is the mean of, and whether its colour was smoothed (for the debug mode)."""
        config = self.config.at_rate(self.fps)
        height = frame.shape[0] if scale_height is None else scale_height
        sigma = config.chroma_sigma_at(grain, height)
        frames = self._recent(frame, config.averaged_frames(road_grey, grain))
        return seen_picture(frames, sigma, rows), len(frames), sigma is not None

    def _recent(self, frame: NDArray[np.uint8], count: int) -> list[NDArray[np.uint8]]:
        """The last `count` frames, `frame` last (fewer while they are stored; for 1, `frame`
        alone, and the stored frames are forgotten)."""
        store = self.recent
        if count <= 1:
            store.clear()
            return [frame]
        if store and store[-1].shape != frame.shape:
            store.clear()
        store.append(frame.copy())
        return list(store)[-count:]

    def view(
        self,
        size: tuple[int, int],
        horizon_y: float | None = None,
        live: tuple[int, int, int, int] | None = None,
        scale_height: float | None = None,
        ground_scale: float = 1.0,
    ) -> View:
        """Where to search frames of `size`: the given horizon, live box, scale and ground
        scale, or the defaults (the whole frame, its height, the tuned camera's height). The
        bands span the live box's width, wherever the road's vanishing point is: it does not
        move them."""
        default = View.default(size, self.config.reference_horizon)
        box = default.live if live is None else live
        return View(
            size,
            default.horizon_y if horizon_y is None else horizon_y,
            box,
            float(box[3] - box[1]) if scale_height is None else scale_height,
            ground_scale,
        )

    def band_rows(self, view: View) -> tuple[int, int]:
        """The rows (top, bottom) the bands span in frames seen as `view`, every band's."""
        spans = [
            band_geometry(band, view, band.patch, self.config.reference_horizon)[1:4:2]
            for band in self.config.bands
        ]
        return min(top for top, _ in spans), max(bottom for _, bottom in spans)

    def scorers_for(
        self, view: View, dark: bool = False, monochrome: bool = False
    ) -> dict[int, Scorer]:
        """The scorer of each band's patch size for pictures seen as `view` (on a `dark` road;
        `monochrome`: without colour, whatever their size or light, where grey scorers exist)."""
        if monochrome and self.grey_scorers:
            return self.grey_scorers
        lowres = view.scale_height < self.config.lowres_rows
        if dark:
            return self.dark_lowres_scorers if lowres else self.dark_scorers
        return self.lowres_scorers if lowres else self.scorers

    def search(
        self,
        frame: NDArray[np.uint8],
        parity: int | None = None,
        view: View | None = None,
        dark: bool = False,
        min_probability: float | None = None,
        monochrome: bool = False,
    ) -> tuple[BandHits, ...]:
        """Window scores of the bands searched this frame (all bands when parity is None), and
        of their mirror images where the window reaches `min_probability` (None: the config's)
        and the config checks them (the scorers `scorers_for` gives)."""
        cfg = self.config
        bands = cfg.bands if parity is None else cfg.bands[parity::2]
        where = view or self.view((frame.shape[1], frame.shape[0]))
        scorers = self.scorers_for(where, dark, monochrome)
        least = cfg.min_probability if min_probability is None else min_probability
        found = (
            search_band(
                frame,
                band,
                scorer.weights,
                where,
                cfg.reference_horizon,
                scorer.verifier_weights,
                scorer.mirrored_weights if cfg.mirror_checks(band) else None,
                scorer.model.decision_at(least),
            )
            for band in bands
            if (scorer := scorers.get(band.patch)) is not None
        )
        return tuple(hit for hit in found if hit is not None)

    def window_terms(
        self,
        hits: Sequence[BandHits],
        view: View,
        dark: bool = False,
        monochrome: bool = False,
    ) -> tuple[NDArray[np.float64], ...]:
        """For every window of `hits`, in order: P(vehicle) by its band's model, its verifier's
        P(vehicle) (1 where that model has none or did not read the window), the weight of its
        heat, and the model's P(vehicle) of its mirror image (1 where not scored). A window steps
        one cell: a 4-cell model's windows step a quarter of their side, the 8-cell model's an
        eighth, so fewer of them overlap a small car: each of its hits heats 8 / 4 = 2 times as
        much (the square, 4, spoilt the boxes of 34-40 px cars; tried)."""
        cells = self.model.config.cells_per_patch
        scorers = self.scorers_for(view, dark, monochrome)
        terms: list[tuple[NDArray[np.float64], ...]] = [(np.zeros(0),) * 4]
        for hit in hits:
            scorer = scorers[hit.band.patch]
            n = len(hit.decisions)
            checked = (
                np.ones(n)
                if scorer.verifier is None or hit.verified is None
                else np.where(
                    np.isnan(hit.verified), 1.0, scorer.verifier.probability(hit.verified)
                )
            )
            mirror = (
                np.ones(n)
                if hit.mirrored is None
                else np.where(np.isnan(hit.mirrored), 1.0, scorer.model.probability(hit.mirrored))
            )
            density = np.full(n, cells / scorer.model.config.cells_per_patch)
            terms.append((scorer.model.probability(hit.decisions), checked, density, mirror))
        return tuple(np.concatenate(part) for part in zip(*terms, strict=True))

    def process(
        self,
        frame: NDArray[np.uint8],
        horizon_y: float | None = None,
        live: tuple[int, int, int, int] | None = None,
        scale_height: float | None = None,
        vanishing_x: float | None = None,
        overlays: tuple[tuple[int, int, int, int], ...] = (),
        ground_scale: float = 1.0,
        road_grey: float | None = None,
        grain: float | None = None,
        monochrome: bool = False,
    ) -> VehicleResult:
        """Detect, accumulate heat, label regions, and track for one undistorted RGB frame
        (bands placed from the scene's `horizon_y`, `live` box and `scale_height` when given,
        their windows sized by `ground_scale`, a car's size at a row against the tuned camera's;
        `vanishing_x` does not move them, boxes reach towards it; windows over `overlays`,
        captions or parts of the car, do not heat; on a dark road, by the scene's `road_grey`,
        the windows read the mean of the last frames and less sure ones heat
        (`DetectorConfig.min_probability_at`); on a road of the scene's `grain` they read the
        picture with its colour smoothed, and from more grain averaged too: `seen`; a picture
        the scene found `monochrome` is read by the grey scorers). A window heats where its
        verifier agrees and, in the larger bands, where it stands by its mirror image
        (`mirror_backed`)."""
        cfg = self.config
        h, w = frame.shape[:2]
        view = self.view((w, h), horizon_y, live, scale_height, ground_scale)
        smallest = cfg.min_box * view.scale_height * view.ground_scale
        parity = self.frame_index % 2 if cfg.interleave else None
        self.frame_index += 1
        dark = cfg.is_dark(road_grey)
        rows = self.band_rows(view)
        seen, averaged, smoothed = self._read(frame, road_grey, grain, view.scale_height, rows)
        # The grey scorers' bound holds where they read the picture (a model of the user's own
        # reads a monochrome one as any other).
        grey = monochrome and bool(self.grey_scorers)
        least = cfg.min_probability_at(road_grey, grey)
        hits = self.search(seen, parity, view, dark, least, grey)
        boxes = np.concatenate([hit.boxes for hit in hits]) if hits else np.zeros((0, 4))
        proba, checked, density, mirror = self.window_terms(hits, view, dark, grey)
        strong = proba >= least
        sure = checked >= cfg.min_verified
        if cfg.min_mirrored is not None:
            backing = strong & sure & (mirror >= least)
            sure &= mirror_backed(boxes, mirror >= cfg.min_mirrored, backing)
        vetoed = boxes[strong & ~sure]
        strong &= sure
        if overlays:
            strong &= covered_share(boxes, overlays) < cfg.max_overlay
        if hits:
            strong &= ~parts_of_larger(hits, boxes, strong)
        # Interleaved frames search half the bands: double their weight to keep heat comparable.
        weight = (2.0 if parity is not None else 1.0) * (proba * density)[strong]
        # Heat is kept over the live picture alone: windows reaching past its sides pile their
        # heat at its edge, as at a frame's edge, not into a black bar.
        lx0, ly0, lx1, ly1 = view.live
        offset = np.array([lx0, ly0, lx0, ly0], np.float64)
        heated = footprint(boxes[strong], cfg.heat_footprint) - offset
        frame_heat = self.heatmap.add((lx1 - lx0, ly1 - ly0), heated, weight)
        region_boxes, peaks = self.heatmap.regions()
        region_boxes = region_boxes + offset
        if cfg.bottom_reach is not None:
            region_boxes = snap_bottoms(
                frame, region_boxes, view.live, cfg.bottom_reach, cfg.bottom_min_rise
            )
        if cfg.top_reach is not None:
            region_boxes = snap_tops(
                frame, region_boxes, view.live, cfg.top_reach, cfg.top_min_change
            )
        big = smaller_sides(region_boxes) >= smallest
        scores = 1.0 - np.exp(-peaks[big] / max(cfg.heat.threshold, 1e-6))
        regions = Detections.from_boxes(region_boxes[big], scores)
        # Tracks may reach past the live picture's side (a car leaving); what is shown stays in it.
        picture = (float(lx0), float(ly0), float(lx1), float(ly1))
        shown = self.tracker.update(regions, picture, view.horizon_y).clipped(picture)
        # A car leaving at the side coasts out with its outer edge held at the picture's edge
        # (its boxes were cut there): once its box is thinner than any found, it has left.
        shown = shown.subset(smaller_sides(shown.boxes) >= smallest)
        velocity = self.tracker.measured_velocities(shown.ids)
        column = (lx0 + lx1) / 2 if vanishing_x is None else vanishing_x
        reached = reach_toward(
            shown.boxes,
            column,
            cfg.side_reach,
            view.live,
            motion=(velocity[:, 0] + velocity[:, 2]) / 2,
            fast=cfg.fast_share,
            tolerance=cfg.heat.scale,
        )
        shown = Detections(reached, shown.scores, shown.ids)
        debug = (
            VehicleDebug(
                hits,
                frame_heat,
                self.heatmap.combined,
                regions,
                cfg.heat.threshold,
                vetoed,
                None if seen is frame else seen,
                averaged,
                smoothed,
                self.tracker.remembered().clipped(picture),
            )
            if self.keep_debug
            else None
        )
        return VehicleResult(shown, debug)
