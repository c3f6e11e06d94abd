"""`Line`: the history of one lane boundary across frames."""

from __future__ import annotations

from collections import deque

import numpy as np

from lanes.search import Fit


class Line:
    """Recent accepted fits of one boundary, their smoothed fit, and how long it went unseen.

    A rejected frame keeps the smoothed fit; after `max_misses` rejections in a row the history is
    dropped, so the finder goes back to a full window search. `turning_off` says the last
    rejection was of a line turning off the lane (see `LaneFinder`), which its next frames go on
    doing.
    """

    def __init__(self, history: int = 5, max_misses: int = 6) -> None:
        self.max_misses = max_misses
        self.fits: deque[Fit] = deque(maxlen=history)
        self.misses = 0
        self.turning_off = False

    @property
    def smoothed(self) -> Fit | None:
        """Mean of the recent fits, the newest weighing most; None without history."""
        if not self.fits:
            return None
        weights = np.arange(1, len(self.fits) + 1, dtype=np.float64)
        return np.asarray(np.average(np.stack(list(self.fits)), axis=0, weights=weights))

    @property
    def trusted(self) -> bool:
        """Whether the history is fresh enough to search around instead of from scratch."""
        return bool(self.fits) and self.misses == 0

    def accept(self, fit: Fit) -> None:
        """Record a fit that passed the sanity checks."""
        self.fits.append(np.asarray(fit, dtype=np.float64))
        self.misses = 0
        self.turning_off = False

    def reject(self, turning_off: bool = False) -> None:
        """Count a frame without a usable fit (`turning_off`: its line turned off the lane);
        forget everything after too many."""
        self.misses += 1
        self.turning_off = turning_off
        if self.misses > self.max_misses:
            self.reset()

    def reset(self) -> None:
        """Forget all history."""
        self.fits.clear()
        self.misses = 0
        self.turning_off = False
