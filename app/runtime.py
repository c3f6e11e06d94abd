"""Process-wide settings that make the per-frame work cheaper; applied once at start-up.

roadview runs its own stages in parallel (lanes beside vehicles, decoding and encoding in other
processes), so native libraries must not start thread pools of their own on top: on the 2-core
target machine OpenBLAS's spinning threads alone burned ~28 ms of CPU per frame (measured).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import threading

import cv2
import numpy as np
from threadpoolctl import threadpool_limits

# glibc mallopt parameters (malloc.h).
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_KEEP_BYTES = 32 * 1024 * 1024  # glibc's largest allowed mmap threshold on 64-bit


def keep_freed_memory() -> bool:
    """Let glibc reuse freed large blocks instead of returning them to the system.

    Every frame allocates the same few-megabyte arrays; by default glibc maps and unmaps each one,
    so every frame pays the page faults again (measured: the HOG step runs 3x slower). Returns
    whether the setting took effect (False off glibc, where it does nothing).
    """
    name = ctypes.util.find_library("c")
    if name is None:
        return False
    try:
        mallopt = ctypes.CDLL(name).mallopt
    except (OSError, AttributeError):
        return False
    mmap_ok: bool = mallopt(_M_MMAP_THRESHOLD, _KEEP_BYTES) == 1
    trim_ok: bool = mallopt(_M_TRIM_THRESHOLD, 8 * _KEEP_BYTES) == 1
    return mmap_ok and trim_ok


def single_threaded_natives() -> None:
    """One thread each for BLAS (numpy's matrix products) and OpenCV; roadview parallelises."""
    threadpool_limits(limits=1)
    cv2.setNumThreads(1)


def tune_process() -> None:
    """Everything above, for a process that is about to process video."""
    keep_freed_memory()
    single_threaded_natives()


def _build_opencv_tables() -> None:
    # The first RGB->LAB conversion builds OpenCV's gamma and LAB tables (~80 ms) and the first
    # text measurement loads the Hershey fonts (~25 ms); both release the GIL meanwhile.
    cv2.cvtColor(np.zeros((1, 1, 3), np.uint8), cv2.COLOR_RGB2LAB)
    cv2.getTextSize("0", cv2.FONT_HERSHEY_SIMPLEX, 1.0, 1)


def warm_up_opencv() -> threading.Thread:
    """Start building OpenCV's one-time tables in a thread; join it before the first frame.

    Started before probing the input, the ~0.1 s of table building overlaps with ffmpeg's probe
    instead of delaying the first frame.
    """
    thread = threading.Thread(target=_build_opencv_tables, name="opencv-warm-up", daemon=True)
    thread.start()
    return thread
