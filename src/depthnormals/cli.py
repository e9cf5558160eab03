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
    An output holds no finite normal (all NaN): no pixel of the input depth is valid, or no
    valid pixel has a valid neighbour (a 1x1 image). A warning on stderr names the file; the
    all-NaN output is still written. The API warns (``NoValidNormalWarning``) instead.
130
    Interrupted (Ctrl-C): "interrupted; run the same command again to resume" on stderr, no
    traceback. Every output is written atomically, so what exists is complete.

Error messages name the file concerned and speak in flags (``--depth-scale``), not in the
library's argument names (:func:`cli_words`).
"""

from __future__ import annotations

import argparse
import importlib
import re
import sys
from collections.abc import Sequence

__all__ = ["COMMANDS", "EXIT_ERROR", "EXIT_INTERRUPTED", "EXIT_NO_VALID_PIXEL", "EXIT_OK", "EXIT_USAGE",
           "cli_words", "main"]

COMMANDS = ("estimate", "methods", "demo", "bench", "evaluate", "ablate", "synth")

EXIT_OK, EXIT_ERROR, EXIT_USAGE, EXIT_NO_VALID_PIXEL = 0, 1, 2, 3
#: Exit status after Ctrl-C (128 + SIGINT, as a shell reports it).
EXIT_INTERRUPTED = 130

#: Library argument names in messages -> the flags of the command line (quoted keys of a
#: camera file, such as ``"depth_scale"``, are left alone).
_FLAG_WORDS = (
    (re.compile(r'(?<!")\bdepth_scale=(?=\S)'), "--depth-scale "),
    (re.compile(r'(?<!")\bdepth_scale\b(?!")'), "--depth-scale"),
    (re.compile(r'(?<!")\bmax_depth\b(?!")'), "--max-depth"),
    (re.compile(r"\(pass shape=\(H, W\)\)"), "(pass --shape H,W)"),
    (re.compile(r" \(resume=False\)"), ""),
    (re.compile(r" \(K=\.\.\.\)"), ""),
)
_EPILOG = """exit status: 0 success; 1 error (bad input, missing file, unknown method or option);
2 usage error; 3 no pixel of the input depth is valid, or no normal could be estimated (warning on
stderr, all-NaN output written); 130 interrupted (run the same command again to resume).
The first command on a fresh install compiles the numba kernels once (announced on stderr)."""


def cli_words(message: str) -> str:
    """A library message in the command line's words: ``depth_scale`` -> ``--depth-scale``,
    ``pass shape=(H, W)`` -> ``pass --shape H,W``, ``max_depth`` -> ``--max-depth``."""
    for pattern, flag in _FLAG_WORDS:
        message = pattern.sub(flag, message)
    return message


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
    except KeyboardInterrupt:
        print(f"\ndepthnormals {args.command}: interrupted; run the same command again to resume",
              file=sys.stderr)
        return EXIT_INTERRUPTED
    except (ValueError, TypeError, FileNotFoundError, ImportError, OSError, MemoryError) as exc:
        text = str(exc) or type(exc).__name__
        if isinstance(exc, MemoryError):
            text = f"out of memory ({text}); is the input or --shape far larger than intended?"
        print(f"depthnormals {args.command}: error: {cli_words(text)}", file=sys.stderr)
        return EXIT_ERROR


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
