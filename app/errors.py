"""The error type for bad input that the CLI reports as one line."""


class InputError(Exception):
    """Bad input or environment; the message names the problem and a fix."""
