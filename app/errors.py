"""The error type for bad input that the CLI reports as one line."""


class InputError(Exception):
    """Bad input or environment; the message names the problem and a fix."""


class Interrupted(Exception):  # noqa: N818 (not an error: a user's choice)
    """Ctrl-C after some work was kept; the message says what was kept and how to go on."""
