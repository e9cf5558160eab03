"""Progress reports on stderr shared by the long-running front ends (evaluate, synth, bench, ablate).

On a terminal: a tqdm bar when tqdm is installed. Anywhere else (a pipe, a log file, a CI job,
or a terminal without tqdm): one plain line per update, so logs never run lines together with
carriage returns.
"""

from __future__ import annotations

import sys
from typing import Any, TextIO

__all__ = ["Progress"]


class Progress:
    """A counter that reports each update on ``stream`` (default: ``sys.stderr`` at creation).

    Parameters
    ----------
    desc : str
        Name shown first (``"evaluate"``, ``"synth"``...).
    total : int, optional
        Number of updates expected, when known.
    unit : str
        What one update counts (``"frame"``, ``"view"``...).
    enabled : bool
        False: report nothing.
    stream : file, optional
        Where to write; default ``sys.stderr``.
    """

    def __init__(self, desc: str, *, total: int | None = None, unit: str = "it",
                 enabled: bool = True, stream: TextIO | None = None) -> None:
        self.desc, self.total, self.unit, self.enabled = desc, total, unit, enabled
        self.stream = sys.stderr if stream is None else stream
        self.count = 0
        self.bar: Any = None
        if enabled and _isatty(self.stream):
            try:
                from tqdm import tqdm
            except ImportError:
                tqdm = None
            if tqdm is not None:
                self.bar = tqdm(total=total, desc=desc, unit=unit, file=self.stream)

    def update(self, postfix: str = "", *, line: str | None = None) -> None:
        """Count one step; ``postfix`` is shown after the count, ``line`` replaces the plain line."""
        self.count += 1
        if self.bar is not None:
            if postfix:
                self.bar.set_postfix_str(postfix, refresh=False)
            self.bar.update(1)
        elif self.enabled:
            if line is None:
                of = f"/{self.total}" if self.total is not None else ""
                line = f"{self.desc}: {self.count}{of} {self.unit}" + (f" {postfix}" if postfix else "")
            print(line, file=self.stream, flush=True)

    def close(self) -> None:
        """End the bar (plain lines need no ending)."""
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _isatty(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # closed or file-like without isatty
        return False
