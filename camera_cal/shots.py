"""Cuts in the footage: where an edited video (a compilation, a zoomed replay) jumps to another
shot, whose camera, horizon and road have nothing to do with the last frame's.

Driving footage changes little from one frame to the next when seen very small: on the shared
and wild clips a 32x18 grey thumbnail moves by at most 16 grey levels a pixel (15 entering the
challenge clip's underpass), and the frame's colours (a hue and saturation histogram) by at most
15 % of their mass.
The LA clip's cuts to a zoomed view and back move them by 49-52 levels and 38-46 %.
An edited video also fades through black from one shot to the next, where no frame moves
much: the fade in from black is a cut too. Its frames are blends of black and the new
picture, so the middle frame of half a second of it is the mean of its ends; driving's never
is (at least 0.32 of the ends' change away from it on the shared and wild clips, where they
changed as much as at a cut), and a tunnel's picture is never all black.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from camera_cal.scene import SceneGeometry


@dataclass(frozen=True)
class ShotConfig:
    """A cut is a frame whose thumbnail differs from the last one's by more than `min_change`
    grey levels a pixel on average and whose colours moved by more than `min_colour_change` of
    their histogram's mass: both, so that a flash or a tunnel (light alone) is no cut."""

    thumbnail: tuple[int, int] = (32, 18)  # (width, height)
    min_change: float = 30.0
    min_colour_change: float = 0.25
    hue_bins: int = 16
    saturation_bins: int = 8
    # A shot cut back to is the same camera's where the parts of one's own car and the burnt-in
    # captions of the shot left (at least this share of the frame) look as they did then (mean
    # grey change under this).
    min_static_share: float = 0.02
    max_static_change: float = 12.0
    # A fade in from black: a black thumbnail (every pixel darker than this) that `fade_frames`
    # later is half way to a picture `fade_frames` after that, which differs from it as a cut
    # does; half way is within this share of their mean change (0.04-0.05 for ffmpeg's fade
    # through black; the least for driving: 0.32). Only after a picture in the shot (its mean
    # at least as light), so a video that starts black (a camera starting up) is one shot,
    # and the dim frame a quick fade out cut to is no picture.
    black_level: float = 24.0
    fade_frames: int = 6
    max_fade_residual: float = 0.15


@dataclass(frozen=True, eq=False)
class Signature:
    """What a frame is compared by: its grey thumbnail and its normalised colour histogram."""

    thumbnail: NDArray[np.float32]
    colours: NDArray[np.float32]


def signature(frame: NDArray[np.uint8], config: ShotConfig | None = None) -> Signature:
    """The `Signature` of one RGB frame."""
    cfg = config if config is not None else ShotConfig()
    # A picture of 8x the thumbnail's side picked from the frame's pixels, then averaged down
    # by whole factors: the layout and the colours at a tenth of the cost of averaging every
    # pixel (0.15 ms a frame at 720p or 1080p against 1.5-3.5).
    width, height = cfg.thumbnail
    picked = cv2.resize(frame, (width * 8, height * 8), interpolation=cv2.INTER_NEAREST)
    colour = cv2.resize(picked, (width * 4, height * 4), interpolation=cv2.INTER_AREA)
    small = cv2.resize(colour, cfg.thumbnail, interpolation=cv2.INTER_AREA)
    grey = cv2.cvtColor(small, cv2.COLOR_RGB2GRAY).astype(np.float32)
    hsv = cv2.cvtColor(colour, cv2.COLOR_RGB2HSV)
    bins = [cfg.hue_bins, cfg.saturation_bins]
    hist = cv2.calcHist([hsv], [0, 1], None, bins, [0, 180, 0, 256]).astype(np.float32)
    return Signature(grey, hist / max(float(hist.sum()), 1.0))


def is_cut(before: Signature, after: Signature, config: ShotConfig | None = None) -> bool:
    """Whether `after` starts another shot than `before`'s."""
    cfg = config if config is not None else ShotConfig()
    change = float(np.abs(after.thumbnail - before.thumbnail).mean())
    colour_change = 0.5 * float(np.abs(after.colours - before.colours).sum())
    return change > cfg.min_change and colour_change > cfg.min_colour_change


def is_black(sig: Signature, config: ShotConfig | None = None) -> bool:
    """Whether a frame's thumbnail is black all over (a fade's darkest frame)."""
    cfg = config if config is not None else ShotConfig()
    return float(sig.thumbnail.max()) < cfg.black_level


def is_fade_in(
    before: Signature, middle: Signature, after: Signature, config: ShotConfig | None = None
) -> bool:
    """Whether `before` (black), `middle` and `after` are a fade in from black to another shot:
    `after` differs from `before` as a cut does and `middle` is their mean, as a blend is."""
    cfg = config if config is not None else ShotConfig()
    if not is_black(before, cfg) or not is_cut(before, after, cfg):
        return False
    change = float(np.abs(after.thumbnail - before.thumbnail).mean())
    mean = (before.thumbnail + after.thumbnail) / 2
    return float(np.abs(middle.thumbnail - mean).mean()) < cfg.max_fade_residual * change


def same_camera(
    before: NDArray[np.uint8],
    after: NDArray[np.uint8],
    scene: SceneGeometry,
    config: ShotConfig | None = None,
) -> bool:
    """Whether RGB frame `after` is of the camera whose frame `before` had the geometry `scene`:
    its bonnet and overlays (a mirror, a caption), where those cover enough of the frame, look
    the same in both. A picture without such parts does not tell: False."""
    cfg = config if config is not None else ShotConfig()
    height, width = before.shape[:2]
    if after.shape != before.shape:
        return False
    still = np.zeros((height, width), bool)
    if scene.bonnet_y is not None:
        still[scene.bonnet_y :] = True
    for x0, y0, x1, y1 in scene.overlays:
        still[y0:y1, x0:x1] = True
    if still.mean() < cfg.min_static_share:
        return False
    grey = [cv2.cvtColor(f, cv2.COLOR_RGB2GRAY).astype(np.int16) for f in (before, after)]
    return float(np.abs(grey[1] - grey[0])[still].mean()) < cfg.max_static_change


class ShotDetector:
    """History for the cuts: the signatures of the shot's last `2 * fade_frames + 1` frames
    (`recent`: the last one's for a cut, all of them for a fade in from black; `lit`: a frame
    of the shot before them was a picture, not a dark one)."""

    def __init__(self, config: ShotConfig | None = None) -> None:
        self.config = config if config is not None else ShotConfig()
        self.recent: deque[Signature] = deque()
        self.lit = False

    def reset(self) -> None:
        """Forget the last frames: the next one starts the footage."""
        self.recent.clear()
        self.lit = False

    def update(self, frame: NDArray[np.uint8]) -> bool:
        """Whether `frame` starts a new shot (never the first frame): a cut from the last
        frame, or the end of a fade in from black after a picture."""
        cfg = self.config
        current, window = signature(frame, cfg), 2 * cfg.fade_frames + 1
        cut = bool(self.recent) and is_cut(self.recent[-1], current, cfg)
        if len(self.recent) == window:
            left = self.recent.popleft()
            self.lit = self.lit or float(left.thumbnail.mean()) >= cfg.black_level
        self.recent.append(current)
        if not cut and self.lit and len(self.recent) == window:
            cut = is_fade_in(self.recent[0], self.recent[cfg.fade_frames], current, cfg)
        if cut:  # the new shot's frames start here
            self.recent.clear()
            self.recent.append(current)
            self.lit = False
        return cut
