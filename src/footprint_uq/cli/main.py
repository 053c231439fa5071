"""The ``footprint-uq`` command line: the group, its error policy and the registry of commands.

Each command lives in a module of its own (``cli/locate.py``, ``cli/map.py``, ...) that only
parses arguments, calls one library function and prints.  To add one, define a
``click.Command`` in a new module and register it at the bottom of this file with one
``main.add_lazy_command(NAME, "footprint_uq.cli.MODULE:ATTRIBUTE")`` line: the module is
imported only when the command runs or a help page lists it, so that a command does not pay for
the start-up of the others (matplotlib, OpenCV, pyarrow, ...).

Error policy: bad input (missing/unknown keys, wrong units, impossible values,
unreadable files, bad options) prints **one line** naming the field on stderr
and exits with status 2, never a traceback.  Warnings are printed as one line
too.  Input files that are not UTF-8, or not valid JSON/YAML, are bad input as
well, wherever they are read.  Anything else is a bug: the last-resort handler prints one line saying so
and exits with status 3 (``footprint-uq --debug COMMAND ...`` or
``FOOTPRINT_UQ_DEBUG=1`` shows the traceback).  No known input may reach it
(``tests/test_hostile.py``).
"""

from __future__ import annotations

import importlib
import json
import os
import re
import sys
import traceback
import warnings

import click
import yaml

from ..errors import FootprintUQError
from .groups import SuggestingGroup

__all__ = ["main", "FootprintUQGroup", "EXIT_BAD_INPUT", "EXIT_BUG"]

#: exit status of every bad-input error
EXIT_BAD_INPUT = 2
#: exit status of an unexpected error (a bug): one line, the traceback with --debug
EXIT_BUG = 3
#: what click raises for a group run without a command (click >= 8.2; a never-raised class before)
_NO_COMMAND = getattr(click.exceptions, "NoArgsIsHelpError", type("_NeverRaised", (Exception,), {}))


def _debug(args) -> bool:
    argv = sys.argv[1:] if args is None else list(args)
    return "--debug" in argv or os.environ.get("FOOTPRINT_UQ_DEBUG", "") not in ("", "0")


def _one_line(text: str) -> str:
    return re.sub(r"\s+", " ", str(text)).strip()


def _error(msg: str) -> None:
    click.echo(f"footprint-uq: error: {_one_line(msg)}", err=True)


def _showwarning(message, category, filename, lineno, file=None, line=None):
    click.echo(f"footprint-uq: warning: {category.__name__}: {_one_line(message)}", err=True)


def _is_yaml_error(e: BaseException) -> bool:
    return isinstance(e, yaml.YAMLError)


def _bug(e: BaseException, args) -> None:
    """Last line of defence: an unexpected exception is a bug: one line, exit 3 (traceback with --debug)."""
    if _debug(args):
        traceback.print_exception(e)
    _error(f"internal error ({type(e).__name__}: {_one_line(e)[:300]}); please report it with the "
           "command line (run with --debug for the traceback)")
    sys.exit(EXIT_BUG)


class FootprintUQGroup(SuggestingGroup):
    """A click group that turns bad-input exceptions into one-line messages and exit status 2.

    Commands are added as usual (:meth:`add_command`) or lazily (:meth:`add_lazy_command`): a
    lazy command's module is imported when the command is first looked up (it runs, or a help
    page lists it).
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.lazy_commands: dict[str, str] = {}

    def add_lazy_command(self, name: str, import_path: str) -> None:
        """Register the command ``name`` found at ``import_path`` (``"package.module:attribute"``)."""
        self.lazy_commands[name] = import_path

    def list_commands(self, ctx) -> list[str]:
        return sorted({*super().list_commands(ctx), *self.lazy_commands})

    def get_command(self, ctx, cmd_name):
        if cmd_name not in self.commands and cmd_name in self.lazy_commands:
            module, _, attribute = self.lazy_commands[cmd_name].partition(":")
            self.add_command(getattr(importlib.import_module(module), attribute), cmd_name)
        return super().get_command(ctx, cmd_name)

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        old = warnings.showwarning
        warnings.showwarning = _showwarning
        try:
            rv = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except click.exceptions.Exit as e:  # --help, --version
            sys.exit(e.exit_code)
        except _NO_COMMAND as e:  # a group without its command: the usage and the commands, as written
            click.echo(e.ctx.get_help() if e.ctx is not None else e.format_message(), err=True)
            _error("missing command: one of those listed above")
            sys.exit(EXIT_BAD_INPUT)
        except click.Abort:
            click.echo("footprint-uq: aborted", err=True)
            sys.exit(1)
        except click.UsageError as e:
            _error(e.format_message())
            sys.exit(EXIT_BAD_INPUT)
        except click.ClickException as e:  # FileError and friends: bad input too
            _error(e.format_message())
            sys.exit(EXIT_BAD_INPUT)
        except FootprintUQError as e:
            _error(str(e))
            sys.exit(EXIT_BAD_INPUT)
        except BrokenPipeError:  # output piped into head & co.
            sys.exit(0)
        except OSError as e:  # unreadable / unwritable file
            name = getattr(e, "filename", None)
            _error(f"{name}: {e.strerror or e}" if name else str(e))
            sys.exit(EXIT_BAD_INPUT)
        except UnicodeDecodeError as e:  # a text file that is not UTF-8 (readers that name the file raise earlier)
            _error(f"an input file is not UTF-8 text (byte 0x{e.object[e.start]:02x} at offset {e.start}); "
                   "save it as UTF-8")
            sys.exit(EXIT_BAD_INPUT)
        except json.JSONDecodeError as e:  # a JSON input file that does not parse
            _error(f"an input file is not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})")
            sys.exit(EXIT_BAD_INPUT)
        except Exception as e:  # noqa: BLE001 - YAML errors are bad input; anything else is a bug
            if _is_yaml_error(e):
                _error(f"an input file is not valid YAML ({_one_line(str(e).splitlines()[0] if str(e) else e)})")
                sys.exit(EXIT_BAD_INPUT)
            _bug(e, args)
        except KeyboardInterrupt:
            click.echo("footprint-uq: interrupted", err=True)
            sys.exit(130)
        finally:
            warnings.showwarning = old
        sys.exit(rv if isinstance(rv, int) else 0)


@click.group(cls=FootprintUQGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="footprint-uq", prog_name="footprint-uq")
@click.option("--debug", is_flag=True, help="Show the traceback of an internal error (exit status 3).")
def main(debug):
    """footprint-uq: ground position and 2x2 covariance of roadside-camera pixels and detections.

    Frames and units: docs/conventions.md.  File formats: docs/file-formats.md.
    """


# -- the registry: one line per command (module imported on first use) -----------------------
main.add_lazy_command("locate", "footprint_uq.cli.locate:locate_cmd")
main.add_lazy_command("map", "footprint_uq.cli.map:map_cmd")
main.add_lazy_command("presets", "footprint_uq.cli.presets:presets_cmd")
main.add_lazy_command("demo", "footprint_uq.cli.demo:demo_cmd")
main.add_lazy_command("case-study", "footprint_uq.cli.case_study:case_study")
main.add_lazy_command("carla", "footprint_uq.cli.carla:carla")
main.add_lazy_command("calibrate", "footprint_uq.cli.calibrate:calibrate")
main.add_lazy_command("objects", "footprint_uq.cli.objects:objects_cmd")
main.add_lazy_command("fuse", "footprint_uq.cli.fuse:fuse_cmd")
main.add_lazy_command("serve", "footprint_uq.cli.serve:serve_cmd")
main.add_lazy_command("convert", "footprint_uq.cli.convert:convert_cmd")
main.add_lazy_command("validate", "footprint_uq.cli.validate:validate_cmd")
main.add_lazy_command("plan", "footprint_uq.cli.plan:plan_cmd")
main.add_lazy_command("camera", "footprint_uq.cli.camera:camera")
main.add_lazy_command("warmup", "footprint_uq.cli.warmup:warmup_cmd")


if __name__ == "__main__":  # pragma: no cover
    main()
