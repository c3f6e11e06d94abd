"""The small interface through which a frame stage (lanes, vehicles) runs in a worker process."""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray


class FrameStage(Protocol):
    """A stage sees every undistorted RGB frame in order and may keep history between frames."""

    def process(self, frame: NDArray[np.uint8]) -> object:
        """Analyse one frame; history classes update here."""
        ...

    def reset(self) -> None:
        """Forget all history (a new clip starts)."""
        ...
