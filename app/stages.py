"""The small interface through which frame stages (lanes, vehicles) plug into the pipeline."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray


class StageResult(Protocol):
    """What a stage found in one frame; it knows its own record form."""

    def to_record(self) -> Any:
        """JSON-ready value stored under the stage's key in the per-frame record."""
        ...


class FrameStage(Protocol):
    """A stage sees every undistorted RGB frame in order and may keep history between frames."""

    record_key: str

    def process(self, frame: NDArray[np.uint8]) -> StageResult:
        """Analyse one frame; history classes update here."""
        ...

    def reset(self) -> None:
        """Forget all history (a new clip starts)."""
        ...
