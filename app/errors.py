"""Errors the user can fix, and the one line that says what is wrong and what to do.

The stage packages' errors state facts (a size, a path, a count); `describe` adds the fix in the
words of roadview's command line, which those packages do not know.
"""

from __future__ import annotations

from camera_cal import CalibrationError, CalibrationMismatch
from camera_cal.calibration import CalibrationFileError, ChessboardImagesError, TooFewBoardsError
from vehicles.dataset import DatasetError
from vehicles.model import ModelError


class InputError(Exception):
    """Bad input or environment; the message names the problem and a fix."""


class Interrupted(Exception):  # noqa: N818 (not an error: a user's choice)
    """Ctrl-C after some work was kept; the message says what was kept and how to go on."""


class FrameSizeChanged(Exception):  # noqa: N818 (a fact about the input, worded by the CLI)
    """A frame of another size than the one the pipeline was prepared for."""

    def __init__(self, expected: tuple[int, int], got: tuple[int, int]) -> None:
        super().__init__(f"frame size changed from {expected} to {got} mid-stream")
        self.expected = expected
        self.got = got


USER_ERRORS: tuple[type[Exception], ...] = (
    InputError,
    CalibrationError,
    DatasetError,
    ModelError,
    FrameSizeChanged,
)


def describe(error: Exception) -> str:
    """The one line a user sees for an expected failure: the library's facts and what to do."""
    fixes: list[tuple[type[Exception], str]] = [
        (CalibrationMismatch, "calibrate this camera or pass --calibration none"),
        (
            CalibrationFileError,
            "make one with 'roadview calibrate' or pass --calibration FILE|none",
        ),
        (ChessboardImagesError, "pass --images DIR with .jpg/.png photos of the chessboard"),
        (
            TooFewBoardsError,
            "check --board (inner corners, e.g. 9x6), or give more and more varied views of "
            "the board (photos, or a video of it moved about the picture, near and far, tilted)",
        ),
        (ModelError, "retrain with 'make train' or pass another --model"),
        (DatasetError, "gather the data with 'make data' or pass --data DIR"),
    ]
    for kind, fix in fixes:
        if isinstance(error, kind):
            return f"{error}; {fix}"
    if isinstance(error, FrameSizeChanged):
        return (
            f"the video's frame size changes from {error.expected[0]}x{error.expected[1]} to "
            f"{error.got[0]}x{error.got[1]} mid-stream; re-encode it to one size (e.g. ffmpeg "
            "-vf scale) and process it again"
        )
    return str(error)
