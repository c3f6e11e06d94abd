"""The error type for bad input that the CLI reports as one line."""


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
