"""Ego motion from the road itself: how far the road surface moved between two bird's-eye frames.

In the bird's-eye view the road moves straight down the image as the car drives forward, so the
shift between consecutive views (phase correlation of their lightness) is the distance driven.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable

import cv2
import numpy as np
from numpy.typing import NDArray

NEAR_PART = 0.6  # the nearest 60 % of the view: road surface, rarely a vehicle


def dft_rows(rows: int) -> int:
    """The largest even row count up to `rows` that the DFT takes without padding: OpenCV's
    phase correlation is half a pixel off when it pads to an odd size (measured: 7.5 for 7)."""
    for n in range(rows - rows % 2, 1, -2):
        if cv2.getOptimalDFTSize(n) == n:
            return n
    return rows


def road_shift(
    previous: NDArray[np.float32],
    current: NDArray[np.float32],
    min_response: float = 0.2,
    hidden: NDArray[np.bool_] | None = None,
) -> float | None:
    """Rows the road moved towards the camera from `previous` to `current` (same-size grey
    bird's-eye images), or None when the correlation peak is too weak to trust. `hidden`
    pixels (vehicles: one beside us at our speed stays put in the view and reads as no motion)
    get no weight, with a soft edge so the mask adds no pattern of its own."""
    window = cv2.createHanningWindow((current.shape[1], current.shape[0]), cv2.CV_32F)
    if hidden is not None and hidden.any():
        grown = cv2.dilate(hidden.astype(np.uint8), np.ones((5, 5), np.uint8))
        window = window * (1.0 - cv2.blur(grown.astype(np.float32), (9, 9)))
    # Copies: with a window, OpenCV multiplies its inputs by it in place.
    (_, dy), response = cv2.phaseCorrelate(previous.copy(), current.copy(), window)
    return float(dy) if response >= min_response else None


def road_texture(grey: NDArray[np.float32], block: int = 8) -> float:
    """The median over `block`-pixel squares of their grey-level spread: how much surface the
    road shows, paint aside (an unlit road at night, or one flattened by compression: none)."""
    rows, cols = grey.shape[0] // block, grey.shape[1] // block
    if rows == 0 or cols == 0:
        return 0.0
    part = np.asarray(grey[: rows * block, : cols * block], np.float32)
    # Each square's mean and mean square (area averages), so its variance in one pass.
    mean = cv2.resize(part, (cols, rows), interpolation=cv2.INTER_AREA)
    square = cv2.resize(part * part, (cols, rows), interpolation=cv2.INTER_AREA)
    return float(np.median(np.sqrt(np.maximum(square - mean * mean, 0.0))))


def trimmed_mean(values: Iterable[float], cut: float) -> float:
    """Mean of the values left after dropping the `cut` share at each end (as
    scipy.stats.trim_mean; numpy alone keeps scipy off the frame path)."""
    ordered = np.sort(np.fromiter(values, np.float64))
    drop = int(cut * len(ordered))
    return float(ordered[drop : len(ordered) - drop].mean())


class RoadMotion:
    """History for ego motion: the previous view and the recent advances (the mean of the middle
    60 % of the last `smoothing` frames: single measurements scatter by up to 20 %, a car's speed
    does not; a plain median is biased where the scatter is lopsided).

    A frame whose near road differs from the previous one by less than `repeat_level` grey levels
    on average is a repeat (video converted from a variable frame rate repeats frames; a moving
    road changes by several levels): it is not measured, and the next shift is spread over the
    frames since the last new one. A road whose texture (`road_texture`) is under `min_texture`
    grey levels does not show whether it moves (solid lines on black asphalt look the same at
    any speed): it is not measured either, and the oldest measurement ages out each such frame.

    What stays put in every view (solid lines and light along the road, the encoder's rendering
    of flat asphalt, dirt on the windscreen) pulls the correlation towards no motion, most where
    the road moves a pixel or two a frame: a 360-row wild clip read 0.72 of the speed its dashes
    give, project_cut_1 shrunk to 320x180 0.75 of its full size's (0.90 now). So once
    `background_frames` views are in, the shift is read between the views less their running
    mean (each new view weighing 1/`background_frames`; a longer mean kept more of the pull),
    where what stays put is gone; where that finds no peak (a road standing still leaves only
    noise), between the views themselves.

    Still light that changes (a glared windscreen's reflections) stays in the views less their
    mean too, and pulls some frames' shift to none: the LA clip's road, whose dashes pass every
    16 frames, read as standing in 7 of every 20 frames in places and in its first 20 frames.
    A pull only ever shortens a shift, so the advance leaves out the measurements under
    `pulled_share` of the recent ones' upper quartile (a car cannot halve its speed in the
    0.6 s they span); once most of them read a standing road (a stop), so does the quartile.
    Under `still_advance` metres a frame (4.5 km/h at 25 fps) the quartile is the noise of a
    standing road, and every measurement counts.
    """

    def __init__(
        self,
        smoothing: int = 15,
        min_response: float = 0.2,
        repeat_level: float = 0.25,
        min_texture: float = 0.3,
        background_frames: int = 5,
        pulled_share: float = 0.5,
        still_advance: float = 0.05,
    ) -> None:
        self.min_response = min_response
        self.repeat_level = repeat_level
        self.min_texture = min_texture
        self.background_frames = background_frames
        self.pulled_share = pulled_share
        self.still_advance = still_advance
        self.recent: deque[float] = deque(maxlen=smoothing)
        self._previous: NDArray[np.float32] | None = None
        self._frames = 1  # frames from the previous new view to this one
        self._background: NDArray[np.float32] | None = None  # running mean of the views
        self._views = 0  # views in the running mean

    def new_view(self) -> None:
        """Forget the previous view and the running mean of the views, keeping the recent
        advances: a new warp shows the road otherwise, but the car drives on as fast (the
        advances are in metres)."""
        self._previous = None
        self._frames = 1
        self._background, self._views = None, 0

    def update(
        self,
        birdseye_rgb: NDArray[np.uint8],
        ym_per_px: float,
        hidden: NDArray[np.bool_] | None = None,
    ) -> float | None:
        """Metres the car advanced since the previous frame (smoothed over the recent measurements),
        or None until a measurement is trusted; `hidden` (the view's size) marks vehicles."""
        grey = cv2.cvtColor(birdseye_rgb, cv2.COLOR_RGB2GRAY)
        rows = dft_rows(round(grey.shape[0] * NEAR_PART))
        near = np.asarray(grey[-rows:], np.float32)
        previous = self._previous
        if road_texture(near) < self.min_texture:
            if self.recent:
                self.recent.popleft()
            self._previous, self._frames = near, 1
            return self.advance
        if previous is not None and previous.shape == near.shape:
            if float(cv2.norm(near, previous, cv2.NORM_L1)) < self.repeat_level * near.size:
                self._frames += 1  # a repeated frame: the road has not been seen to move
                return self.advance
            still = None if hidden is None else hidden[-rows:]
            shift = None
            background = self._background
            if background is not None and self._views >= self.background_frames:
                shift = road_shift(
                    previous - background, near - background, self.min_response, still
                )
            if shift is None:
                shift = road_shift(previous, near, self.min_response, still)
            if shift is not None:
                self.recent.extend([shift * ym_per_px / self._frames] * self._frames)
        self._remember(near)
        self._previous, self._frames = near, 1
        return self.advance

    def _remember(self, near: NDArray[np.float32]) -> None:
        """Add a view to the running mean (a new mean when the view's size changed)."""
        if self._background is None or self._background.shape != near.shape:
            self._background, self._views = near.copy(), 1
            return
        self._views += 1
        weight = 1.0 / min(self._views, self.background_frames)
        self._background += weight * (near - self._background)

    @property
    def advance(self) -> float | None:
        """Metres a frame, smoothed over the recent measurements that were not pulled short;
        None before the first."""
        if not self.recent:
            return None
        measured = np.fromiter(self.recent, np.float64)
        level = float(np.percentile(np.abs(measured), 75))
        if level > self.still_advance:
            measured = measured[np.abs(measured) >= self.pulled_share * level]
        return trimmed_mean(measured, 0.2)


class SideMotion:
    """History for the road's advance in the view's left and right `share` of its width (a
    `RoadMotion` each): in a picture turned by a camera mounted askew, the view takes the road
    on the side it turns up as further off than it lies, and that side's road moves faster in
    the view (see `turn_from_advances`)."""

    def __init__(self, smoothing: int = 15, share: float = 1 / 3) -> None:
        self.share = share
        self.left, self.right = RoadMotion(smoothing), RoadMotion(smoothing)

    def new_view(self) -> None:
        """Forget both sides' previous views (see `RoadMotion.new_view`)."""
        self.left.new_view()
        self.right.new_view()

    def columns(self, width: int) -> tuple[slice, slice]:
        """The view's columns of the left and right sides, for a view `width` wide."""
        part = round(width * self.share)
        return slice(0, part), slice(width - part, width)

    def update(
        self,
        birdseye_rgb: NDArray[np.uint8],
        ym_per_px: float,
        hidden: NDArray[np.bool_] | None = None,
    ) -> tuple[float, float] | None:
        """The left and right sides' advances (metres a frame, smoothed), or None until both
        are measured; `hidden` as in `RoadMotion.update`."""
        advances = []
        for side, cols in zip(
            (self.left, self.right), self.columns(birdseye_rgb.shape[1]), strict=True
        ):
            part = np.ascontiguousarray(birdseye_rgb[:, cols])
            advances.append(
                side.update(part, ym_per_px, None if hidden is None else hidden[:, cols])
            )
        left, right = advances
        return None if left is None or right is None else (left, right)


def turn_from_advances(
    advances: tuple[float, float], slopes: tuple[float, float], least: float = 0.05
) -> float | None:
    """The picture's turn in degrees anticlockwise (as `--roll` counts) that the road's
    advances in the view at two columns read, the columns along rays from the vanishing point
    with `slopes` t (sideways over down, in frame pixels). A road point at depth Z seen at t in
    a picture turned by a lies on a row the view takes as depth Z (1 + t tan a): the view's
    advance there is the car's times (1 + t tan a), whatever the camera's height, pitch or
    lens. None where either side advances under `least` metres a frame (a standing road)."""
    (left, right), (t_left, t_right) = advances, slopes
    if min(left, right) < least:
        return None
    return float(np.degrees(np.arctan((right - left) / (left * t_right - right * t_left))))
