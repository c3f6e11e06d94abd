"""Which way up a picture is, read off its sky: the side of the picture that is brightest and
bluest. A dashcam stored turned (mounted upside down, a phone's video that lost its rotation
tag) has its sky on another side than the top. One frame can mislead (a bright road under a
dark wooded skyline, snow, a tunnel), so a clip's verdict is a vote over many frames."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from camera_cal.scene import Box, live_box

# The picture's sides in the order of `sky_scores`; side k lies 90k degrees clockwise of the top.
SIDES = ("top", "right", "bottom", "left")


@dataclass(frozen=True)
class UprightConfig:
    """How the sky vote is taken: every `every`-th frame is scored; a frame votes for its
    best side when it beats the next by `margin` (grey levels plus blue over red); a clip is
    turned when at least `min_votes` frames voted and `least` of them chose one side other than
    the top. The shared and wild upright clips give the top 73-100 % of their votes (README,
    Which way up)."""

    every: int = 5
    strip: float = 0.2
    margin: float = 30.0
    least: float = 0.8
    min_votes: int = 10


def sky_scores(rgb: NDArray[np.uint8], live: Box, strip: float = 0.2) -> NDArray[np.float64]:
    """How sky-like each side strip of the live box `live` is (top, right, bottom, left): the
    median grey plus the median of blue over red, on every 4th row and column. Each strip is
    `strip` of the box's extent across it, so a picture turned by quarter turns permutes the
    scores and changes none of them."""
    x0, y0, x1, y1 = live
    picture = rgb[y0:y1:4, x0:x1:4].astype(np.int16)
    if picture.size == 0:
        return np.zeros(4)
    grey = picture.sum(axis=2) // 3
    blue = picture[..., 2] - picture[..., 0]
    h, w = grey.shape
    dy, dx = max(1, round(h * strip)), max(1, round(w * strip))
    strips = (
        (slice(0, dy), slice(None)),
        (slice(None), slice(w - dx, w)),
        (slice(h - dy, h), slice(None)),
        (slice(None), slice(0, dx)),
    )
    return np.array([float(np.median(grey[s]) + np.median(blue[s])) for s in strips])


def sky_side(scores: NDArray[np.float64], margin: float = 30.0) -> int | None:
    """The side (index into `SIDES`) whose score beats every other's by `margin`, or None when
    no side stands out (an overcast, snowy or dark frame)."""
    ranked = np.argsort(scores)[::-1]
    if scores[ranked[0]] - scores[ranked[1]] < margin:
        return None
    return int(ranked[0])


def frame_sky(rgb: NDArray[np.uint8], live: Box | None, config: UprightConfig) -> int | None:
    """One frame's vote: the side its sky stands out on within `live` (None: the whole frame),
    or None where no side stands out."""
    h, w = rgb.shape[:2]
    scores = sky_scores(rgb, live or (0, 0, w, h), config.strip)
    return sky_side(scores, config.margin)


@dataclass(frozen=True)
class SkyVote:
    """A clip's sky vote: the votes each side got, and the turn that stands it upright."""

    votes: tuple[int, int, int, int]  # frames whose sky was at the top, right, bottom, left
    side: int | None  # the side holding the vote, or None (too few votes, or split)

    @property
    def turn_deg(self) -> int | None:
        """The clockwise turn that puts the sky at the top (sky on the right: 270), or None."""
        return None if self.side is None else (360 - 90 * self.side) % 360


def sky_vote(sides: Sequence[int | None], least: float = 0.8, min_votes: int = 10) -> SkyVote:
    """The vote of frames' sky sides (None: unsure, not counted): the side holding `least` of
    at least `min_votes` votes."""
    votes = np.bincount([s for s in sides if s is not None], minlength=4)[:4]
    total = int(votes.sum())
    best = int(np.argmax(votes))
    held = total >= min_votes and votes[best] >= least * total
    return SkyVote(
        votes=(int(votes[0]), int(votes[1]), int(votes[2]), int(votes[3])),
        side=best if held else None,
    )


def frames_vote(frames: Sequence[NDArray[np.uint8]], config: UprightConfig) -> SkyVote:
    """The sky vote of `frames` (RGB, as sampled by the caller), each scored within the live
    box their brightest values give (black bars are no sky)."""
    if not frames:
        return sky_vote([], config.least, config.min_votes)
    brightest = np.max([f.max(axis=2) for f in frames], axis=0)
    live = live_box(brightest.max(axis=1), brightest.max(axis=0))
    sides = [frame_sky(f, live, config) for f in frames]
    return sky_vote(sides, config.least, config.min_votes)
