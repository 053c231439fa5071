"""Exception types.

Every error raised on bad input names the field, the value and what was
expected, in one line, so that the CLI can print it without a traceback.
"""

from __future__ import annotations

__all__ = ["FootprintUQError", "InputError", "ConfigError", "ConsistencyWarning"]


class FootprintUQError(Exception):
    """Base class of all errors raised by footprint-uq."""


def _fmt_value(value: object) -> str:
    try:
        text = repr(value)
    except ValueError:  # an integer beyond Python's int -> str digit limit
        text = f"<{type(value).__name__} too long to print>"
    # a long value keeps its start and its end (a long path keeps its file name)
    return text if len(text) <= 80 else text[:38] + "..." + text[-39:]


class InputError(FootprintUQError, ValueError):
    """A value given by the user is not acceptable.

    Parameters
    ----------
    field : str
        Name of the offending field, e.g. ``"height_m"`` or ``"camera.yaml: K"``.
    value : object
        The value that was given.
    expected : str
        What was expected, e.g. ``"a finite number > 0"``.
    """

    def __init__(self, field: str, value: object, expected: str):
        self.field = field
        self.value = value
        self.expected = expected
        super().__init__(f"{field}: got {_fmt_value(value)}, expected {expected}")


class ConfigError(InputError):
    """A camera, budget or scenario file is malformed (missing/unknown keys, wrong units)."""


class ConsistencyWarning(UserWarning):
    """A calibration file is internally inconsistent (e.g. P differs from K[R|t])."""
