"""The small interface through which a frame stage (lanes, vehicles) runs in a worker process."""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray


class FrameStage(Protocol):
    """A stage sees every undistorted RGB frame in order and may keep history between frames.

    `process` also takes the scene as plain values (the horizon row, the live box inside black
    bars, the height its tuned fractions are of, the road's vanishing point's column, the boxes
    of burnt-in captions): the stages do not import the scene module, nor each other."""

    def process(
        self,
        frame: NDArray[np.uint8],
        horizon_y: float | None = None,
        live: tuple[int, int, int, int] | None = None,
        scale_height: float | None = None,
        vanishing_x: float | None = None,
        overlays: tuple[tuple[int, int, int, int], ...] = (),
    ) -> object:
        """Analyse one frame; history classes update here."""
        ...

    def reset(self, fps: float | None = None) -> None:
        """Forget all history (a new clip starts); with `fps`, its frames come at that rate,
        which the history's frame counts follow so as to cover the same time."""
        ...
