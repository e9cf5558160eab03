"""``depthnormals methods``: list the registered estimators."""

from __future__ import annotations

import argparse

HELP = "list the estimators (names for --method) with their options"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--names-only", action="store_true", help="print names only")


def run(args: argparse.Namespace) -> int:
    import inspect

    from ..registry import get_estimator, methods

    ddm_opts: tuple[str, ...] = ()
    if any(name.endswith("+") for name in methods()):
        from ..ddm import discontinuity_discrimination

        ddm_opts = tuple(
            p.name for p in inspect.signature(discontinuity_discrimination).parameters.values()
            if p.kind is inspect.Parameter.KEYWORD_ONLY and p.name != "depth_scale"
        )
    for name in methods():
        if args.names_only:
            print(name)
            continue
        info = get_estimator(name.rstrip("+"))
        if name.endswith("+"):
            print(f"{name:<18} {info.name} followed by the discontinuity discrimination module  "
                  f"[options: {', '.join(info.options + ddm_opts)}]")
            continue
        print(f"{name:<18} {info.summary}  [options: {', '.join(info.options) or '-'}]")
    return 0
