"""A stage in a worker process gives the same outputs, in order, as running in-process."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from app.workers import StageWorker


@dataclass(frozen=True)
class Seen:
    """What a toy stage saw: its own frame count and the frame's mean."""

    count: int
    mean: float


class Counter:
    """A stage with history: counts frames since the last reset; fails on request."""

    def __init__(self, key: str, fail_at: int | None = None) -> None:
        self.key = key
        self.count = 0
        self.fail_at = fail_at

    def process(
        self,
        frame: np.ndarray,
        horizon_y: float | None = None,
        live: tuple[int, int, int, int] | None = None,
        scale_height: float | None = None,
        vanishing_x: float | None = None,
        overlays: tuple[tuple[int, int, int, int], ...] = (),
    ) -> Seen:
        self.count += 1
        if self.count == self.fail_at:
            raise ValueError(f"{self.key} failed on frame {self.count}")
        return Seen(self.count, float(frame.mean()))

    def reset(self, fps: float | None = None) -> None:
        self.count = 0


def _frames(n: int, size: tuple[int, int] = (32, 24)) -> list[np.ndarray]:
    rng = np.random.default_rng(1)
    return [rng.integers(0, 255, (size[1], size[0], 3), dtype=np.uint8) for _ in range(n)]


def _through_worker(stage: Counter, frames: list[np.ndarray]) -> list[Seen]:
    """Each frame submitted and its result collected one frame later, as the pipeline does."""
    worker = StageWorker(stage, frame_bytes=frames[0].nbytes)
    try:
        out: list[Seen] = []
        for k, frame in enumerate(frames):
            worker.submit(frame)
            if k:
                out.append(worker.collect()[0])  # type: ignore[arg-type]
        out.append(worker.collect()[0])  # type: ignore[arg-type]
        worker.reset()
        worker.submit(frames[0])
        out.append(worker.collect()[0])  # type: ignore[arg-type]
        return out
    finally:
        worker.close()


def test_worker_matches_in_process_order_and_history() -> None:
    frames = _frames(7)
    here = Counter("b")
    expected = [here.process(f) for f in frames] + [Seen(1, float(frames[0].mean()))]
    assert _through_worker(Counter("b"), frames) == expected  # reset() restarts the history


def test_a_reset_before_the_next_frame_leaves_the_frames_in_flight_alone() -> None:
    """A cut in the footage: the frame in flight keeps its history, the next starts afresh,
    and nothing waits for the child."""
    frames = _frames(5)
    worker = StageWorker(Counter("c"), frame_bytes=frames[0].nbytes)
    try:
        worker.submit(frames[0])
        worker.submit(frames[1])  # two in flight
        first = worker.collect()[0]
        worker.reset_before_next(25.0)
        worker.submit(frames[2])  # after the reset
        seen = [first, worker.collect()[0], worker.collect()[0]]
        worker.submit(frames[3])
        seen.append(worker.collect()[0])
    finally:
        worker.close()
    assert [s.count for s in seen] == [1, 2, 1, 2]  # type: ignore[attr-defined]


def test_pipeline_with_the_vehicle_worker_equals_in_process(
    test_video: Path, data_dir: Path
) -> None:
    """The worker runs one frame ahead of the compositor, also across a cut to another camera
    whose horizon is read ahead: the frame before the cut is measured by its own scene's warp,
    not by the next shot's (the lanes started the cut's frame before the frame before it was
    finished, and its vehicles were put 15-32 m by a warp they were not in)."""
    from app.assembly import build_stages
    from app.pipeline import Pipeline
    from app.record import frame_record
    from app.sources import probe_video, read_frames
    from tests.helpers import zoomed_replay

    info = probe_video(test_video)
    frames = list(read_frames(test_video, info, 0, 12))
    replay = data_dir / "videos" / "project_cut_1.mp4"
    frames += [zoomed_replay(f) for f in read_frames(replay, probe_video(replay), 0, 16)]

    def records(in_worker: bool) -> list[dict[str, Any]]:
        lanes, vehicles = build_stages()
        with Pipeline(None, lanes, vehicles, vehicles_in_worker=in_worker) as pipeline:
            pipeline.prepare(info.size, 25.0)
            pipeline.look_ahead(iter(frames))
            pipeline.frames_from = lambda k: (f for f in frames[k:])
            out = [
                frame_record(k, k / 25.0, info.size, out.result)
                for k, out in enumerate(pipeline.stream(iter(frames)))
            ]
            assert pipeline.cuts == [12]
            return out

    alone, in_worker = records(False), records(True)
    assert alone[11]["vehicles"] and alone[12]["lane"]  # the replay's horizon read ahead
    assert in_worker == alone


def test_worker_error_reaches_the_caller_and_the_child_stops() -> None:
    stage = Counter("b", fail_at=2)
    worker = StageWorker(stage, frame_bytes=32 * 24 * 3)
    frames = _frames(2)
    worker.submit(frames[0])
    worker.submit(frames[1])
    assert worker.collect()[0] == Seen(1, float(frames[0].mean()))
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


def test_worker_exits_when_its_parent_is_killed(test_video: Path, tmp_path: Path) -> None:
    """A `process` killed outright (SIGKILL, no clean-up) leaves no vehicle worker behind
    holding its output pipes open."""
    import os
    import signal
    import subprocess
    import sys
    import time

    command = [
        sys.executable,
        "-m",
        "app",
        "process",
        str(test_video),
        "-o",
        str(tmp_path / "o.mp4"),
        "--json",
        str(tmp_path / "o.jsonl"),
    ]
    main = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 60
    while time.time() < deadline and not any(
        p.stat().st_size > 0 for p in tmp_path.glob(".o.*.tmp.jsonl")
    ):
        time.sleep(0.01)
    children = Path(f"/proc/{main.pid}/task/{main.pid}/children").read_text().split()
    workers = [int(c) for c in children if b"python" in Path(f"/proc/{c}/cmdline").read_bytes()]
    assert workers, "the vehicle worker process was not found"
    os.kill(main.pid, signal.SIGKILL)
    main.wait()
    time.sleep(2.0)
    alive = [
        w
        for w in workers
        if Path(f"/proc/{w}").exists()
        and "Z" not in Path(f"/proc/{w}/stat").read_text().rsplit(")", 1)[1].split()[0]
    ]
    assert not alive
