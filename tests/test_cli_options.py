"""Every option of every command, checked: a float option given ``nan``, ``inf`` or ``-inf`` and a list or
range option given an empty or non-monotone list exit 2 with one line naming the option (issue 35, part 2).

The commands are walked from the click tree (the CLI's root group), so an option added later is walked too:
a new ``type=float`` option that takes NaN fails :func:`test_float_options_refuse_non_finite`.
"""

from __future__ import annotations

import click
import pytest
from click.testing import CliRunner

from footprint_uq.cli.common import AscendingFloats, FiniteFloat, FiniteFloatRange
from footprint_uq.cli.main import main

#: Float options whose non-finite values are meaningful and documented in their help: (command path, option,
#: value).  Empty on purpose: no option of the command line takes nan / inf / -inf today (a limit that can be
#: "none" is the option's absence, not inf).  An entry here needs its meaning in the option's help text.
ALLOWED_NON_FINITE: set[tuple[str, str, str]] = set()

#: Tuple options of floats that are a (min, max) range: the pair reversed must be refused.
RANGE_PAIRS = {("calibrate synthetic", "--fill")}
#: Tuple options of floats that are not ranges (a point, a pixel; by option name, in any command): no order.
NOT_RANGE_PAIRS = {"--position-m", "--pixel"}


def _walk(group: click.Group, prefix: tuple[str, ...] = ()):
    ctx = click.Context(group)
    for name in group.list_commands(ctx):
        cmd = group.get_command(ctx, name)
        if isinstance(cmd, click.Group):
            yield from _walk(cmd, (*prefix, name))
        else:
            yield (*prefix, name), cmd


COMMANDS = list(_walk(main))


def _float_types(opt: click.Option) -> list[click.ParamType]:
    """The float types of an option's values (several for a tuple option), empty for a non-float option."""
    types = opt.type.types if isinstance(opt.type, click.Tuple) else [opt.type]
    return [t for t in types if isinstance(t, click.types.FloatParamType)]


def _options(kind):
    out = []
    for path, cmd in COMMANDS:
        for opt in cmd.params:
            if isinstance(opt, click.Option) and not opt.is_flag and kind(opt):
                out.append(pytest.param(path, opt, id=f"{' '.join(path)} {opt.opts[-1]}"))
    return out


FLOAT_OPTIONS = _options(lambda o: bool(_float_types(o)))
LIST_OPTIONS = _options(lambda o: isinstance(o.type, AscendingFloats))


def _valid(t: click.ParamType) -> str:
    """A value inside a float type's range (the other members of a tuple option)."""
    lo = getattr(t, "min", None)
    hi = getattr(t, "max", None)
    if lo is not None and hi is not None:
        return repr((lo + hi) / 2)
    if lo is not None:
        return repr(lo + 1.0)
    return repr(hi - 1.0) if hi is not None else "1.0"


def _invoke(path, opt, values):
    """The command with only this option: click converts options in the order of the command line, so the
    option's error comes before any 'Missing option' of a required one."""
    return CliRunner().invoke(main, [*path, opt.opts[-1], *values])


def _assert_refused(r, opt, value):
    err = r.stderr.strip()
    assert r.exit_code == 2, (opt.opts[-1], value, r.exit_code, r.output)
    assert len(err.splitlines()) == 1, err
    assert err.startswith("footprint-uq: error:"), err
    # the message names the option and the value: not a 'Missing option' of another one
    assert any(name in err for name in opt.opts), err
    assert "Missing" not in err and "Traceback" not in err, err


def test_the_walk_sees_every_command():
    paths = {" ".join(p) for p, _ in COMMANDS}
    assert {"locate", "map", "validate", "plan", "serve", "calibrate budget", "calibrate gcp", "fuse",
            "objects"} <= paths
    assert len(FLOAT_OPTIONS) >= 40 and len(LIST_OPTIONS) >= 1


@pytest.mark.parametrize(("path", "opt"), FLOAT_OPTIONS)
def test_float_options_refuse_non_finite(path, opt):
    types = _float_types(opt)
    assert len(types) == (len(opt.type.types) if isinstance(opt.type, click.Tuple) else 1)
    for value in ("nan", "inf", "-inf", "NaN", "1e400"):
        if (" ".join(path), opt.opts[-1], value) in ALLOWED_NON_FINITE:
            continue
        for k in range(len(types)):  # the value in each member of a tuple option, the others valid
            values = [value if j == k else _valid(t) for j, t in enumerate(types)]
            _assert_refused(_invoke(path, opt, values), opt, value)


@pytest.mark.parametrize(("path", "opt"), FLOAT_OPTIONS)
def test_float_options_use_the_shared_finite_types(path, opt):
    # the behaviour is checked above; this names the fix for a new option: cli/common.py's types
    for t in _float_types(opt):
        assert isinstance(t, FiniteFloat | FiniteFloatRange), (path, opt.opts, t)


@pytest.mark.parametrize(("path", "opt"), LIST_OPTIONS)
@pytest.mark.parametrize("value", ["", ",", "50,25", "0,25,25", "0,nan", "nan", "0,inf", "-5,10", "0,,10", "a,b"])
def test_list_options_refuse_empty_and_non_monotone(path, opt, value):
    _assert_refused(_invoke(path, opt, [value]), opt, value)


def test_tuple_options_are_classified():
    tuples = {(" ".join(p), o.opts[-1]) for p, o in (x.values for x in FLOAT_OPTIONS)
              if isinstance(o.type, click.Tuple)}
    unclassified = {t for t in tuples if t not in RANGE_PAIRS and t[1] not in NOT_RANGE_PAIRS}
    assert not unclassified, f"classify these (min, max) or not: {unclassified}"


@pytest.mark.parametrize(("path", "option"), sorted(RANGE_PAIRS))
def test_range_pairs_refuse_reversed(path, option):
    cmd = dict((" ".join(p), c) for p, c in COMMANDS)[path]
    opt = next(o for o in cmd.params if option in o.opts)
    _assert_refused(_invoke(path.split(), opt, ["0.6", "0.3"]), opt, "0.6 0.3")


def test_range_bands_still_parse():
    from footprint_uq.cli.common import AscendingFloats as A

    assert A(0.0).convert("0,25,50,100", None, None) == (0.0, 25.0, 50.0, 100.0)
    assert A(0.0).convert("10", None, None) == (10.0,)
