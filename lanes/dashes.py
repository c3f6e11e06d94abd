"""The spacing of a dashed lane line's dashes, as the road's motion carries them past the camera.

A dashed line repeats a dash and a gap at a fixed spacing along the road (12.19 m on US
highways: a 10 ft dash, a 30 ft gap). The distance the road's motion says we drove between two
dashes' near ends passing the nearer part of the bird's-eye view reads that spacing in the
view's metres, which are right only for the lens the view assumes: the scene compares the two
to scale the distances and speed where the lens is not known (`camera_cal.DashScale`). Read in one
frame instead, from one dash to the next, the spacing depends on the far part of the view,
where a horizon a few rows off stretches the road: test_video's read 12-15 m frame to frame.
"""

from __future__ import annotations

import statistics

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def dashes(painted: NDArray[np.bool_], bridge: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """First rows and rows past the end of each run of `painted` rows, runs fewer than `bridge`
    rows apart joined first (a dash the mask broke in two)."""
    step = np.diff(np.concatenate([[0], painted.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(step == 1), np.flatnonzero(step == -1)
    if len(starts) < 2:
        return starts, stops
    # A run starts a new dash where the gap before it is at least `bridge` rows.
    first = np.concatenate([[True], starts[1:] - stops[:-1] >= bridge])
    last = np.concatenate([first[1:], [True]])
    return starts[first], stops[last]


def near_ends(
    painted: NDArray[np.bool_], ym_per_px: float, bridge_m: float, length_m: tuple[float, float]
) -> FloatArray:
    """The rows just past the near end of each dash of a line's `painted` rows (rows grow
    towards the camera) whose near end is in the view: runs less than `bridge_m` apart joined,
    and only those `length_m` (least, most) long, not cut by the view's top, counted as dashes
    (California's raised markers mid-gap read as short runs; a solid line as one too long)."""
    starts, stops = dashes(painted, max(1, round(bridge_m / ym_per_px)))
    metres = (stops - starts) * ym_per_px
    kept = (starts > 0) & (stops < len(painted)) & (metres >= length_m[0]) & (metres <= length_m[1])
    return stops[kept].astype(np.float64)


class DashTrack:
    """History of one dashed line's dashes as the road carries them towards the camera.

    Each frame's dashes whose near end lies in the nearer part of the view (`near`: the share
    of its rows from the top where that part starts) are placed on the road: the near end's
    distance down the view less the distance driven so far (the road's advances summed) stays
    put for one dash, and an observation within `same_m` of a dash's joins it. A dash that
    leaves that part is closed at the median of its places; the distance from the dash closed
    before it is one spacing (the one nearer the camera, or under a rear camera, whose road
    moves away, the one farther). A frame without the road's motion breaks the chain (the next
    spacing starts afresh)."""

    def __init__(self, near: float = 0.45, same_m: float = 1.5, least: int = 2) -> None:
        self.near = near
        self.same_m = same_m
        self.least = least  # observations a dash needs to be closed
        self.driven = 0.0
        self._open: list[list[float]] = []  # places of the dashes in the nearer part
        self._last: float | None = None  # place of the last dash closed

    def reset(self) -> None:
        """Forget every dash (a new view, a gap in the road's motion)."""
        self._open, self._last = [], None

    def update(
        self, ends: FloatArray, rows: int, ym_per_px: float, advance_m: float | None
    ) -> list[float]:
        """Take in one frame's dash near ends (`near_ends`; empty where the line is not dashed)
        on a view `rows` tall, after the road moved `advance_m` towards the camera (None: not
        measured); the spacings in metres of the view completed this frame."""
        if advance_m is None:
            self.reset()
            return []
        self.driven += advance_m
        inside = ends[ends >= self.near * rows]
        places = inside * ym_per_px - self.driven
        # Each open dash's place, once a frame (the median of a few: statistics', not numpy's,
        # whose call costs 50 times as much on so few).
        centres = [statistics.median(dash) for dash in self._open]
        kept: list[list[float]] = []
        seen: set[int] = set()
        for place in places.tolist():
            j = next((j for j, c in enumerate(centres) if abs(c - place) <= self.same_m), None)
            if j is None:
                kept.append([place])
                continue
            if j not in seen:
                seen.add(j)
                kept.append(self._open[j])
            self._open[j].append(place)
        # Dashes not seen this frame left the nearer part (or were lost), in the order they
        # passed: the nearest first where the road comes towards the camera.
        ahead = advance_m >= 0
        left = [
            c for j, c in enumerate(centres) if j not in seen and len(self._open[j]) >= self.least
        ]
        gone = sorted(left, reverse=ahead)
        spacings: list[float] = []
        for place in gone:
            # The one before passed nearer the camera (a rear camera's: farther); a dash lost
            # for a frame and found again does not read as the next.
            if self._last is not None and (self._last > place) == ahead:
                spacings.append(abs(self._last - place))
            self._last = place
        self._open = kept
        return spacings
