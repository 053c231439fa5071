"""The command line's click group class: an unknown command gets a "did you mean" (``locat`` -> ``locate``).

click suggests close option names itself (``--camra`` -> ``--camera``); for commands it only says "No such
command".  :class:`SuggestingGroup` adds the closest names (:mod:`difflib`) to that one-line error.  The top-level
group (:class:`footprint_uq.cli.main.FootprintUQGroup`) and the ``calibrate``, ``camera`` and ``carla`` groups
use it.
"""

from __future__ import annotations

import difflib

import click

__all__ = ["SuggestingGroup", "close_names"]


def close_names(name: str, names) -> list[str]:
    """Up to three of ``names`` close to ``name`` (difflib's ratio >= 0.6; a prefix of one name counts too)."""
    names = list(names)
    prefixed = [n for n in names if len(name) >= 3 and n.startswith(name)]
    close = difflib.get_close_matches(name, names, n=3, cutoff=0.6)
    return list(dict.fromkeys(prefixed + close))[:3]


class SuggestingGroup(click.Group):
    """A click group whose "No such command" names the closest commands."""

    def resolve_command(self, ctx, args):
        try:
            return super().resolve_command(ctx, args)
        except click.exceptions.NoSuchCommand:
            close = close_names(str(args[0]), self.list_commands(ctx)) if args else []
            if not close:
                raise
            hint = " or ".join(f"'{c}'" for c in close)
            raise click.UsageError(f"No such command '{args[0]}'. Did you mean {hint}?", ctx) from None
