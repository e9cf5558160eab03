"""``depthnormals methods``: list the registered estimators."""

from __future__ import annotations

import argparse

HELP = "list the estimators (names for --method) with their options"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--names-only", action="store_true", help="print names only")


def run(args: argparse.Namespace) -> int:
    from ..registry import get_estimator, methods

    for name in methods():
        if args.names_only:
            print(name)
            continue
        base = name.rstrip("+")
        info = get_estimator(base)
        extra = " + discontinuity discrimination" if name.endswith("+") else ""
        opts = ", ".join(info.options) or "-"
        print(f"{name:<18} {info.summary}{extra}  [options: {opts}]")
    return 0
