"""The pipeline's worker processes give the same outputs, in order, as running in-process."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from app.pipeline import Pipeline
from app.workers import StageWorker


@dataclass(frozen=True)
class Seen:
    """What a toy stage saw: its own frame count and the frame's mean."""

    count: int
    mean: float

    def to_record(self) -> Any:
        return {"count": self.count, "mean": self.mean}


class Counter:
    """A stage with history: counts frames since the last reset; fails on request."""

    def __init__(self, key: str, fail_at: int | None = None) -> None:
        self.record_key = key
        self.count = 0
        self.fail_at = fail_at

    def process(self, frame: np.ndarray) -> Seen:
        self.count += 1
        if self.count == self.fail_at:
            raise ValueError(f"{self.record_key} failed on frame {self.count}")
        return Seen(self.count, float(frame.mean()))

    def reset(self) -> None:
        self.count = 0


def _frames(n: int, size: tuple[int, int] = (32, 24)) -> list[np.ndarray]:
    rng = np.random.default_rng(1)
    return [rng.integers(0, 255, (size[1], size[0], 3), dtype=np.uint8) for _ in range(n)]


def _run(workers: bool, frames: list[np.ndarray]) -> list[dict[str, Any]]:
    with Pipeline(None, [Counter("a"), Counter("b")], workers=workers) as pipeline:
        pipeline.prepare((frames[0].shape[1], frames[0].shape[0]))
        return [
            {key: result.to_record() for key, result in out.results.items()}
            for out in pipeline.stream(iter(frames))
        ]


def test_workers_match_in_process_order_and_history() -> None:
    frames = _frames(7)
    in_process = _run(False, frames)
    assert _run(True, frames) == in_process
    assert [r["b"]["count"] for r in in_process] == list(range(1, 8))
    assert [r["b"]["mean"] for r in in_process] == [float(f.mean()) for f in frames]


def test_prepare_resets_history_in_the_worker() -> None:
    frames = _frames(3)
    with Pipeline(None, [Counter("a"), Counter("b")], workers=True) as pipeline:
        pipeline.prepare((32, 24))
        list(pipeline.stream(iter(frames)))
        pipeline.prepare((32, 24))
        counts = [out.results["b"].to_record()["count"] for out in pipeline.stream(iter(frames))]
    assert counts == [1, 2, 3]


def test_worker_error_reaches_the_caller_and_the_child_stops() -> None:
    stage = Counter("b", fail_at=2)
    worker = StageWorker(stage, frame_bytes=32 * 24 * 3)
    frames = _frames(2)
    worker.submit(frames[0])
    worker.submit(frames[1])
    assert worker.collect()[0].to_record()["count"] == 1
    with pytest.raises(ValueError, match="b failed on frame 2"):
        worker.collect()
    process = worker._process
    worker.close()
    assert not process.is_alive()


def test_frame_larger_than_the_slots_is_refused() -> None:
    worker = StageWorker(Counter("b"), frame_bytes=10)
    try:
        with pytest.raises(RuntimeError, match="slots hold 10"):
            worker.submit(_frames(1)[0])
    finally:
        worker.close()
