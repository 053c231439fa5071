"""Options shared by the ``calibrate`` commands."""

from __future__ import annotations

from ..calibration.boards import parse_board

__all__ = ["board_callback"]


def board_callback(ctx, param, value):
    """click callback of ``--board COLSxROWS``: checks the spelling (InputError naming the field)."""
    parse_board(value)
    return value
