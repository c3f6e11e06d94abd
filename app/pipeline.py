"""The frame pipeline: undistort, run each stage, compose; and the video/still drivers around it."""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from queue import Empty, Queue
from typing import TextIO

from app.atomic import atomic_output
from app.errors import InputError
from app.progress import Progress
from app.record import frame_record, write_record_line
from app.runtime import warm_up_opencv
from app.stages import FrameStage, StageResult
from app.video import Frame, VideoWriter, probe_video, read_frames, read_image, write_image
from app.workers import StageWorker
from camera_cal import Calibration, CalibrationError, Undistorter, build_undistorter

Compositor = Callable[[Frame, Mapping[str, StageResult], float], Frame]


def plain_compositor(frame: Frame, results: Mapping[str, StageResult], fps: float) -> Frame:
    """No overlay: the undistorted frame as it is."""
    return frame


@dataclass
class FrameOutput:
    """Everything the pipeline made of one frame."""

    undistorted: Frame
    results: dict[str, StageResult]
    timings_ms: dict[str, float] = field(default_factory=dict)


class Pipeline:
    """Undistorts frames of one size and runs the stages on them.

    The stages are independent of each other (each sees the undistorted frame). With `workers`,
    every stage but the first runs in a child process (started by the first `prepare`), and
    `stream` keeps one frame in flight so the children work while this process does the rest.
    Use it as a context manager, or call `close`, to stop the children.
    """

    def __init__(
        self, calibration: Calibration | None, stages: Sequence[FrameStage], workers: bool = False
    ) -> None:
        self.calibration = calibration
        self.stages = list(stages)
        self._undistorter: Undistorter | None = None
        self._want_workers = workers and len(self.stages) > 1
        self._workers: list[StageWorker] = []

    def __enter__(self) -> Pipeline:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the worker processes, if any."""
        for worker in self._workers:
            worker.close()
        self._workers = []

    @property
    def _local(self) -> list[FrameStage]:
        """The stages run in this process."""
        return self.stages[:1] if self._workers else self.stages

    def prepare(self, size: tuple[int, int]) -> None:
        """Build the undistortion maps for frames of `size` and reset stage history."""
        self._undistorter = None
        if self.calibration is not None:
            try:
                self._undistorter = build_undistorter(self.calibration, size)
            except CalibrationError as error:
                raise InputError(str(error)) from None
        frame_bytes = size[0] * size[1] * 3
        if self._workers and self._workers[0].frame_bytes < frame_bytes:
            self.close()  # a larger frame than the slots hold: start over
        for stage in self._local:
            stage.reset()
        for worker in self._workers:
            worker.reset()
        if self._want_workers and not self._workers:
            # Forked now, before any reader/writer thread exists, with fresh stage history.
            self._workers = [StageWorker(stage, frame_bytes) for stage in self.stages[1:]]

    def undistort(self, frame: Frame) -> Frame:
        """The undistorted frame (or the frame itself with no calibration)."""
        if self._undistorter is None:
            return frame
        if (frame.shape[1], frame.shape[0]) != self._undistorter.size:
            self.prepare((frame.shape[1], frame.shape[0]))
            assert self._undistorter is not None
        return self._undistorter(frame)

    def run(self, frame: Frame) -> FrameOutput:
        """Undistort one frame and pass it through every stage."""
        return self._finish(self._start(frame))

    def stream(self, frames: Iterator[Frame]) -> Iterator[FrameOutput]:
        """Every frame's output, in order; with workers, one frame is in flight meanwhile."""
        lag = 1 if self._workers else 0
        pending: deque[FrameOutput] = deque()
        for frame in frames:
            pending.append(self._start(frame))
            if len(pending) > lag:
                yield self._finish(pending.popleft())
        while pending:
            yield self._finish(pending.popleft())

    def _start(self, frame: Frame) -> FrameOutput:
        """Undistort, hand the frame to the workers, and run the local stages."""
        t0 = time.perf_counter()
        undistorted = self.undistort(frame)
        out = FrameOutput(undistorted, {}, {"undistort": (time.perf_counter() - t0) * 1000})
        for worker in self._workers:
            worker.submit(undistorted)
        for stage in self._local:
            t0 = time.perf_counter()
            out.results[stage.record_key] = stage.process(undistorted)
            out.timings_ms[stage.record_key] = (time.perf_counter() - t0) * 1000
        return out

    def _finish(self, out: FrameOutput) -> FrameOutput:
        """Add the workers' results for this frame, in stage order."""
        for worker in self._workers:
            out.results[worker.record_key], out.timings_ms[worker.record_key] = worker.collect()
        out.results = {s.record_key: out.results[s.record_key] for s in self.stages}
        return out


def prefetch(frames: Iterator[Frame], depth: int = 4) -> Iterator[Frame]:
    """Decode ahead in a thread so reading the pipe overlaps with processing."""
    queue: Queue[Frame | BaseException | None] = Queue(maxsize=depth)
    stop = threading.Event()

    def pump() -> None:
        try:
            for frame in frames:
                if stop.is_set():
                    break
                queue.put(frame)
            queue.put(None)
        except BaseException as error:  # handed to the consumer, which re-raises it
            queue.put(error)

    thread = threading.Thread(target=pump, daemon=True)
    thread.start()
    try:
        while (item := queue.get()) is not None:
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        while thread.is_alive():
            with contextlib.suppress(Empty):
                queue.get_nowait()
            thread.join(timeout=0.01)


@dataclass(frozen=True)
class RunSummary:
    """What a processing run did."""

    frames: int
    seconds: float
    output: Path | None
    record: Path | None

    @property
    def fps(self) -> float:
        """End-to-end frames per second."""
        return self.frames / self.seconds if self.seconds > 0 else math.inf


def frame_range(fps: float, n_frames: int, start_s: float, end_s: float | None) -> tuple[int, int]:
    """First and one-past-last frame index for a time range in seconds."""
    if start_s < 0 or (end_s is not None and end_s <= start_s):
        raise InputError("--start must be >= 0 and --end later than --start")
    first = round(start_s * fps)
    last = n_frames if end_s is None else min(n_frames, round(end_s * fps))
    if first >= n_frames:
        raise InputError(f"--start {start_s}s is past the end of the video ({n_frames / fps:.2f}s)")
    return first, last


def process_video(
    source: Path,
    output: Path | None,
    pipeline: Pipeline,
    record: Path | None = None,
    compositor: Compositor = plain_compositor,
    start_s: float = 0.0,
    end_s: float | None = None,
) -> RunSummary:
    """Process a video into an annotated video and/or a record; outputs appear only on success.

    With `output` None no video is composed or encoded (the record alone)."""
    warm_up = warm_up_opencv()
    try:
        info = probe_video(source)
        first, last = frame_range(info.fps, info.n_frames, start_s, end_s)
    finally:
        # Before the fork in prepare() no thread may run, nor at exit inside OpenCV (abort).
        warm_up.join()
    pipeline.prepare(info.size)
    started = time.perf_counter()
    count = 0
    progress = Progress(last - first, label=source.name)
    with ExitStack() as outputs:
        # Temporary files are renamed into place only when the block ends without an error.
        handle: TextIO | None = None
        if record is not None:
            handle = outputs.enter_context(outputs.enter_context(atomic_output(record)).open("w"))
        writer = None
        if output is not None:
            writer = VideoWriter(
                outputs.enter_context(atomic_output(output)),
                info.size,
                info.fps,
                audio_from=source if info.has_audio else None,
                audio_start_s=first / info.fps,
                audio_seconds=(last - first) / info.fps,
            )
        try:
            # Without --end every decoded frame is read (the probed count is an estimate).
            decoded = prefetch(
                read_frames(source, info, first, last if end_s is not None else None)
            )
            for offset, out in enumerate(pipeline.stream(decoded)):
                index = first + offset
                if writer is not None:
                    writer.write(compositor(out.undistorted, out.results, progress.fps))
                if handle is not None:
                    line = frame_record(index, index / info.fps, info.size, out.results)
                    write_record_line(handle, line)
                count += 1
                progress.update()
            progress.close()
            expected = last - first
            if count == 0 or count < expected - max(2, expected // 50):
                raise InputError(
                    f"{source} is truncated or damaged: decoded {count} of {expected} frames; "
                    "re-export or re-download the video"
                )
        except BaseException:
            if writer is not None:
                writer.abort()
            raise
        if writer is not None:
            writer.close()
    return RunSummary(count, time.perf_counter() - started, output, record)


def process_still(
    source: Path,
    output: Path,
    pipeline: Pipeline,
    record: Path | None = None,
    compositor: Compositor = plain_compositor,
    log: Callable[[str], None] = lambda message: None,
) -> RunSummary:
    """Process one still image into an annotated image (and a one-line record)."""
    image = read_image(source)
    started = time.perf_counter()
    try:
        pipeline.prepare((image.shape[1], image.shape[0]))
    except InputError as error:
        # A still of another shape is still processed, without undistortion, and says so.
        log(f"note: {error}; processing it without undistortion")
        pipeline.calibration = None
        pipeline.prepare((image.shape[1], image.shape[0]))
    out = pipeline.run(image)
    composed = compositor(out.undistorted, out.results, 0.0)
    with ExitStack() as outputs:
        write_image(outputs.enter_context(atomic_output(output)), composed)
        if record is not None:
            with outputs.enter_context(atomic_output(record)).open("w") as handle:
                write_record_line(
                    handle, frame_record(0, 0.0, (image.shape[1], image.shape[0]), out.results)
                )
    return RunSummary(1, time.perf_counter() - started, output, record)
