"""A frame stage run in a child process, so it works beside the rest of the pipeline.

The stages are numpy/OpenCV code that holds Python's GIL often enough that two of them in
threads of one process run little faster than one after the other (measured). A forked child
has its own interpreter: the caller submits a frame, does its own work, and collects the result
later. The stage (and its loaded model) is inherited by the fork, so nothing is re-loaded.
"""

from __future__ import annotations

import contextlib
import mmap
import multiprocessing
import pickle
import signal
import time
from collections import deque
from multiprocessing.connection import Connection
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.stages import FrameStage


class WorkerError(RuntimeError):
    """The child process died or answered out of turn."""


def _serve(
    stage: FrameStage, conn: Connection, slots: list[mmap.mmap], parent_end: Connection
) -> None:
    """Child loop: frames in, (result, ms) out; errors are sent back instead of raised."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and stops us
    # The fork copied the parent's end of the pipe too: closed here, so that if the parent dies
    # (even killed) this child reads end-of-file and exits instead of waiting for ever.
    parent_end.close()
    while True:
        try:
            command, argument = conn.recv()
        except (EOFError, OSError):
            return
        reply: tuple[str, Any]
        try:
            if command == "frame":
                slot, shape, context = argument
                # A private copy: the parent refills the slot once this frame is collected.
                frame = np.frombuffer(slots[slot], np.uint8, int(np.prod(shape))).reshape(shape)
                frame = frame.copy()
                t0 = time.perf_counter()
                result = stage.process(frame, **context)
                reply = ("ok", (result, (time.perf_counter() - t0) * 1000))
            elif command == "reset":
                stage.reset(argument)
                reply = ("ok", None)
            else:
                return
        except Exception as error:  # handed to the parent, which raises it
            reply = ("error", error)
        try:
            try:
                conn.send(reply)
            except (TypeError, AttributeError, pickle.PicklingError):  # an error that won't pickle
                failure = reply[1]
                conn.send(("error", WorkerError(f"{type(failure).__name__}: {failure}")))
        except (BrokenPipeError, ConnectionError, EOFError, OSError):
            return  # the parent stopped listening (Ctrl-C, or it died): nothing to answer


class StageWorker:
    """One stage in a forked child: `submit` a frame, then `collect` its result, in order.

    Frames travel through shared-memory slots (a pipe would block the sender until the child
    reads), so up to `slots` frames can be in flight.
    """

    def __init__(self, stage: FrameStage, frame_bytes: int, slots: int = 2) -> None:
        self.name = type(stage).__name__
        self.frame_bytes = frame_bytes
        # Anonymous shared maps made before the fork are shared with the child.
        self._slots = [mmap.mmap(-1, max(1, frame_bytes)) for _ in range(slots)]
        context = multiprocessing.get_context("fork")
        self._conn, child = context.Pipe()
        self._process = context.Process(
            target=_serve,
            args=(stage, child, self._slots, self._conn),
            name=f"roadview-{self.name}",
            daemon=True,
        )
        self._process.start()
        child.close()
        self._pending = 0
        self._submitted = 0
        self._reset_next: tuple[float | None] | None = None  # see `reset_before_next`
        # Per frame in flight, whether a reset was sent just before it (its answer comes first).
        self._after_reset: deque[bool] = deque()

    def submit(self, frame: NDArray[np.uint8], **context: Any) -> None:
        """Hand over one frame (and keyword arguments for the stage's `process`, such as the
        scene's horizon); the child starts on it as soon as it is free (after forgetting the
        stage's history first, if `reset_before_next` asked for it)."""
        if self._pending >= len(self._slots):
            raise WorkerError(f"more than {len(self._slots)} frames in flight")
        if frame.nbytes > self.frame_bytes:
            raise WorkerError(f"frame of {frame.nbytes} bytes; slots hold {self.frame_bytes}")
        slot = self._submitted % len(self._slots)
        # Written through the mmap itself: no array view of it outlives this call (an
        # interrupt here must not keep the slot from closing).
        self._slots[slot].seek(0)
        self._slots[slot].write(np.ascontiguousarray(frame).data.cast("B"))
        reset, self._reset_next = self._reset_next, None
        if reset is not None:  # in turn: the frames in flight keep the history they had
            self._conn.send(("reset", reset[0]))
        self._after_reset.append(reset is not None)
        self._conn.send(("frame", (slot, frame.shape, context)))
        self._pending += 1
        self._submitted += 1

    def collect(self) -> tuple[object, float]:
        """The oldest submitted frame's result and the ms the stage spent on it."""
        if self._pending == 0:
            raise WorkerError("collect() without a submitted frame")
        self._pending -= 1
        if self._after_reset.popleft():
            self._answer()  # the reset's
        result: tuple[object, float] = self._answer()
        return result

    def reset_before_next(self, fps: float | None = None) -> None:
        """Forget the stage's history, now for frames at `fps`, before the next frame submitted
        (the frames in flight are done with the history they had; nothing waits)."""
        self._reset_next = (fps,)

    def reset(self, fps: float | None = None) -> None:
        """Forget the stage's history, now for frames at `fps` (waits for frames in flight)."""
        while self._pending:
            self.collect()
        self._reset_next = None
        self._conn.send(("reset", fps))
        self._answer()

    def close(self) -> None:
        """Stop the child (it also dies with the parent: it is a daemon)."""
        with contextlib.suppress(OSError, ValueError):
            self._conn.send(("stop", None))
        self._conn.close()
        self._process.join(timeout=2)
        if self._process.is_alive():
            self._process.kill()
            self._process.join()
        for slot in self._slots:
            slot.close()

    def _answer(self) -> Any:
        try:
            status, value = self._conn.recv()
        except (EOFError, OSError):
            raise WorkerError(
                f"the {self.name} worker process died (exit code {self._process.exitcode})"
            ) from None
        if status == "error":
            raise value
        return value
