"""Durable per-(frame, method) results, the CSV, and atomic JSON/text writes."""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from ..io import atomic_write

__all__ = ["FIELDS", "PartStore", "read_results_csv", "write_json", "write_results_csv",
           "write_text"]

#: Columns of ``results.csv``, one row per (frame, method). Shares (a5 ... a30, coverage) are
#: fractions in [0, 1]; errors in degrees; ``ms`` the estimator's wall time for the frame.
FIELDS = (
    "group", "frame", "method", "mean_deg", "median_deg", "rmse_deg", "a5", "a11_25",
    "a22_5", "a30", "coverage", "near_mean_deg", "smooth_mean_deg", "count", "scored",
    "covered", "near_count", "smooth_count", "ms",
)
_INT_FIELDS = {"count", "scored", "covered", "near_count", "smooth_count"}
_STR_FIELDS = {"group", "frame", "method"}


def write_text(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) atomically."""
    with atomic_write(path, "w") as fh:
        fh.write(text)


def _clean(obj: Any) -> Any:
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.generic):
        return _clean(obj.item())
    return obj


def write_json(path: Path, data: Any) -> None:
    """Write ``data`` as indented JSON atomically (NaN and inf become null)."""
    write_text(path, json.dumps(_clean(data), indent=2, sort_keys=False) + "\n")


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return repr(value)
    return str(value)


def write_results_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    """Write the rows (dicts with :data:`FIELDS`) as CSV, atomically; floats at full precision."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(FIELDS)
    for row in rows:
        writer.writerow([_fmt(row[k]) for k in FIELDS])
    write_text(path, buf.getvalue())


def read_results_csv(path: str | Path) -> list[dict[str, Any]]:
    """Read a ``results.csv`` back: ints and floats typed, strings kept."""
    out = []
    with open(path, newline="") as fh:
        for rec in csv.DictReader(fh):
            row: dict[str, Any] = {}
            for k, v in rec.items():
                row[k] = v if k in _STR_FIELDS else (int(v) if k in _INT_FIELDS else float(v))
            out.append(row)
    return out


class PartStore:
    """One small file per finished (frame, method) under ``<out>/parts/``.

    A part is keyed by a hash of everything that determines its numbers (dataset, frame and
    its data, method and options, protocol, the library's code); it is written atomically, so
    after an interruption every part present is complete, and a resumed run reuses exactly
    those.
    """

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)

    @staticmethod
    def key(**fields: Any) -> str:
        """Hash of the JSON of ``fields`` (sorted keys)."""
        text = json.dumps(fields, sort_keys=True, separators=(",", ":"))
        return hashlib.sha1(text.encode()).hexdigest()[:24]

    def _path(self, key: str) -> Path:
        return self.root / key[:2] / f"{key}.npz"

    def load(self, key: str) -> tuple[dict[str, Any], np.ndarray] | None:
        """The stored (row, histogram) of ``key``, or None if absent or unreadable."""
        path = self._path(key)
        if not path.is_file():
            return None
        try:
            with np.load(path, allow_pickle=False) as data:
                row = json.loads(str(data["row"][()]))
                hist = np.zeros(int(data["nbins"][()]), np.int64)
                hist[data["bins"]] = data["counts"]
        except (OSError, ValueError, KeyError, zipfile.BadZipFile, json.JSONDecodeError):
            return None
        return row, hist

    def save(self, key: str, row: dict[str, Any], hist: np.ndarray) -> None:
        """Store a finished (row, histogram) atomically (the histogram sparsely)."""
        path = self._path(key)
        path.parent.mkdir(exist_ok=True)
        bins = np.flatnonzero(hist)
        with atomic_write(path) as fh:
            np.savez(fh, row=np.array(json.dumps(row)), nbins=np.array(hist.size),
                     bins=bins.astype(np.int32), counts=hist[bins].astype(np.int64))
