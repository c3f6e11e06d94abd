"""Process-wide settings that make the per-frame work cheaper; applied once at start-up.

roadview runs its own stages in parallel (lanes beside vehicles, decoding and encoding in other
processes), so native libraries must not start thread pools of their own on top: on the 2-core
target machine OpenBLAS's spinning threads alone burned ~28 ms of CPU per frame (measured).
"""

from __future__ import annotations

import ctypes
import ctypes.util

import cv2
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
