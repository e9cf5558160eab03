"""Command-line interface: a thin layer over the library (``main(argv) -> int``).

Each sub-command lives in ``depthnormals.commands.<name>`` and provides ``HELP`` (one line),
``add_arguments(parser)`` and ``run(args) -> int``; a command that compiles numba kernels also
sets ``FIRST_RUN_S``, its compile time on a cold cache, which the first-run announcement
quotes. Add a command by adding its module name to ``COMMANDS``.

Exit status
-----------
0
    Success.
1
    Error: bad input, missing file, unknown method or option (a message on stderr).
2
    Usage error: unknown command or option, missing argument (argparse's message).
3
    Nothing to estimate: no pixel of the input depth is valid (a warning on stderr; the
    all-NaN output is still written).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

__all__ = ["COMMANDS", "EXIT_ERROR", "EXIT_NO_VALID_PIXEL", "EXIT_OK", "EXIT_USAGE", "main"]

COMMANDS = ("estimate", "methods", "demo", "bench", "evaluate", "ablate", "synth")

EXIT_OK, EXIT_ERROR, EXIT_USAGE, EXIT_NO_VALID_PIXEL = 0, 1, 2, 3

_EPILOG = """exit status: 0 success; 1 error (bad input, missing file, unknown method or option);
2 usage error; 3 no pixel of the input depth is valid (warning on stderr, all-NaN output written).
The first command on a fresh install compiles the numba kernels once (announced on stderr)."""


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every sub-command."""
    from . import __version__

    parser = argparse.ArgumentParser(
        prog="depthnormals", description="Surface normals from depth images.", epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"depthnormals {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        mod = importlib.import_module(f"depthnormals.commands.{name}")
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run, _first_run_s=getattr(mod, "FIRST_RUN_S", None))
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit status (see the module docstring: 0 ok, 1 error, 2 usage
    error, 3 no valid depth pixel). argparse's usage errors raise ``SystemExit(2)``."""
    from .commands._firstrun import announce_first_run

    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return EXIT_USAGE
    try:
        announce_first_run(args.command, args._first_run_s)
        return int(args._run(args) or 0)
    except (ValueError, TypeError, FileNotFoundError, ImportError, OSError) as exc:
        print(f"depthnormals {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_ERROR


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
