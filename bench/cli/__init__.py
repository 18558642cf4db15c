"""The `bench` command line. In: the user's arguments. Out: calls to the stages,
and every error as one line with a non-zero exit.

One module per command (`HELP`, `DESCRIPTION`, `add_arguments`, `run`); the shared
options in `bench.cli.common`.

Only the command being run gets its arguments (and imports what they need), so `bench
plot` and `bench publish` never load COLMAP, OpenCV or Mitsuba.
"""

from __future__ import annotations

import importlib
import os
import signal
import sys

from bench import DISTRIBUTION, BenchError, __version__
from bench.cli.common import Parser

COMMANDS = (
    "scenes",
    "render",
    "run",
    "reproduce",
    "verdict",
    "plot",
    "publish",
    "upgrade",
    "train-weights",
    "train-matchability",
    "select",
    "frontend",
    "export",
    "gallery",
)


NATIVE = (
    "run",
    "reproduce",
    "verdict",
    "upgrade",
    "train-weights",
    "train-matchability",
    "select",
    "frontend",
    "export",
)
"""The commands that load COLMAP, whose import installs glog's failure signal handler (a
native stack dump on SIGTERM): it is imported before ours replaces that handler."""


def command_module(name: str):
    return importlib.import_module(f"bench.cli.{name.replace('-', '_')}")


def build_parser(only: str | None = None) -> Parser:
    """The parser of every command; with `only`, only that command gets its arguments."""
    p = Parser(
        prog="bench",
        description="Rendered-scene benchmark of keypoint selection policies for 3D reconstruction.",
    )
    p.add_argument("--version", action="version", version=f"bench {__version__} ({DISTRIBUTION})")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        module = command_module(name)
        command = sub.add_parser(name, help=module.HELP, description=module.DESCRIPTION)
        if only is None or only == name:
            module.add_arguments(command)
        command.set_defaults(func=module.run)
    return p


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where Python is running so that cleanup code runs (an interrupt)."""


def _terminate(signum, frame):
    raise Terminated


def _interrupted(e: BaseException) -> BaseException | None:
    """The interrupt behind an exception (a renderer wraps Ctrl-C in a RuntimeError)."""
    while e is not None:
        if isinstance(e, KeyboardInterrupt):
            return e
        e = e.__cause__ or e.__context__
    return None


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    only = next((a for a in argv if not a.startswith("-")), "")
    try:
        args = build_parser(only if only in COMMANDS else "").parse_args(argv)
    except BenchError as e:  # an option's default could not be computed
        print(f"bench: error: {e}", file=sys.stderr)
        return 2
    # our handler, not the one COLMAP's logging library installs (it aborts the process,
    # leaving lock files and half-written entries behind); the caller's again on return
    if args.command in NATIVE:
        import pycolmap  # noqa: F401
    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        args.func(args)
    except BenchError as e:
        print(f"bench: error: {e}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # the reader of a listing stopped (`bench scenes | head`)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # nothing more to say
        return 141  # as a shell's tools end on a closed pipe (128 + SIGPIPE)
    except OSError as e:  # a file that cannot be written or read: what was written is kept
        where = e.filename2 or e.filename or "a file"  # a rename: its target
        print(
            f"bench: error: {where}: {e.strerror or e}; what was already written is kept",
            file=sys.stderr,
        )
        return 2
    except BaseException as e:
        stop = _interrupted(e)
        if stop is None:
            raise
        if isinstance(stop, Terminated):
            print("bench: terminated; finished work is kept", file=sys.stderr)
            return 143
        print("bench: interrupted; finished work is kept", file=sys.stderr)
        return 130
    finally:  # None: a handler not set from Python, which cannot be set back
        signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)
    return 0


if __name__ == "__main__":
    sys.exit(main())
