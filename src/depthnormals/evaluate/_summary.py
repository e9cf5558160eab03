"""Summaries per group and method: the paper's e_A, pooled metrics, edges vs smooth, speed."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from ._protocol import HIST_BIN_DEG

__all__ = ["ALL_GROUPS", "check_group_levels", "group_levels_key", "pooled_median", "summarize",
           "summary_markdown", "threshold_curve"]

#: Name of the pseudo-group pooling every frame (present when there are several groups).
ALL_GROUPS = "(all)"


def group_levels_key(levels: Sequence[int]) -> Callable[[str], str]:
    """A ``group_key`` keeping the given "/"-separated components of a group name.

    Examples
    --------
    >>> group_levels_key([0, 2])("indoor/room-03/clean")
    'indoor/clean'
    """
    levels = [int(i) for i in levels]
    if not levels:
        raise ValueError("group levels must name at least one component (0-based)")

    def key(group: str) -> str:
        check_group_levels(levels, group)
        parts = group.split("/")
        return "/".join(parts[i] for i in levels)

    return key


def check_group_levels(levels: Sequence[int], group: str) -> None:
    """ValueError when a level names no component of ``group`` (levels may count from the end).

    A level past the end of a name used to be dropped, and a name with none left was kept
    whole: ``--group-levels 3`` on ``indoor/room-03/clean`` summarised every group apart,
    silently.
    """
    n = len(group.split("/"))
    bad = [int(i) for i in levels if not -n <= int(i) < n]
    if bad:
        raise ValueError(f"group level(s) {bad} name no component of the group {group!r} "
                         f"({n} '/'-separated components: levels 0..{n - 1} or -{n}..-1)")


def pooled_median(hist: np.ndarray) -> float:
    """Median of the errors counted in ``hist`` (bins of :data:`HIST_BIN_DEG` degrees).

    Linear interpolation inside the bin holding the middle error: exact to one bin width.
    """
    n = int(hist.sum())
    if n == 0:
        return float("nan")
    cum = np.cumsum(hist)
    target = n / 2.0
    k = int(np.searchsorted(cum, target))
    before = cum[k - 1] if k else 0
    return float((k + (target - before) / hist[k]) * HIST_BIN_DEG)


def threshold_curve(hist: np.ndarray, thresholds: np.ndarray) -> np.ndarray:
    """Share of errors below each threshold (degrees, multiples of the bin width)."""
    n = hist.sum()
    cum = np.concatenate([[0], np.cumsum(hist)])
    k = np.clip(np.round(np.asarray(thresholds) / HIST_BIN_DEG).astype(np.int64), 0, hist.size)
    return cum[k] / n if n else np.full(k.shape, np.nan)


def _wmean(values: np.ndarray, weights: np.ndarray) -> float:
    ok = weights > 0
    w = weights[ok].sum()
    return float((values[ok] * weights[ok]).sum() / w) if w else float("nan")


def _aggregate(rows: list[dict[str, Any]], hist: np.ndarray) -> dict[str, Any]:
    def col(name: str) -> np.ndarray:
        return np.array([r[name] for r in rows], dtype=np.float64)

    count = col("count")
    means = col("mean_deg")
    per_image = means[count > 0]
    ms = col("ms")
    scored = col("scored")
    return {
        "frames": len(rows),
        "e_A": float(per_image.mean()) if per_image.size else float("nan"),
        "mean": _wmean(means, count),
        "median": pooled_median(hist),
        "rmse": math.sqrt(_wmean(col("rmse_deg") ** 2, count)) if count.sum() else float("nan"),
        "a5": _wmean(col("a5"), count),
        "a11_25": _wmean(col("a11_25"), count),
        "a22_5": _wmean(col("a22_5"), count),
        "a30": _wmean(col("a30"), count),
        "coverage": float(col("covered").sum() / scored.sum()) if scored.sum() else 0.0,
        "near_mean": _wmean(col("near_mean_deg"), col("near_count")),
        "smooth_mean": _wmean(col("smooth_mean_deg"), col("smooth_count")),
        "near_share": float(col("near_count").sum() / count.sum()) if count.sum() else 0.0,
        "count": int(count.sum()),
        "ms_median": float(np.median(ms)) if ms.size else float("nan"),
        "ms_mean": float(ms.mean()) if ms.size else float("nan"),
    }


def summarize(rows: Sequence[dict[str, Any]], hists: Mapping[tuple[str, str], np.ndarray],
              labels: Sequence[str], *, group_key: Callable[[str], str] | None = None,
              curve_max: float = 90.0, curve_step: float = 0.25) -> dict[str, Any]:
    """Aggregate per-(frame, method) rows into per-(group, method) summaries.

    Parameters
    ----------
    rows : sequence of dict
        Rows of ``results.csv`` (see :data:`FIELDS`).
    hists : mapping (group, label) -> ndarray
        Error histograms (bins of :data:`HIST_BIN_DEG`) summed over the frames of each
        (group, method label) of ``rows``.
    labels : sequence of str
        Method labels, in the order to report them.
    group_key : callable, optional
        Maps a row's group to the group it is summarised under (default: itself), e.g.
        ``"indoor/room-03/clean" -> "indoor/clean"``.
    curve_max, curve_step : float
        Grid (degrees) of the error-vs-threshold curves.

    Returns
    -------
    dict
        ``{"groups": {group: {label: {...}}}, "curves": {"thresholds": [...],
        group: {label: [...]}}}``; ``e_A`` is the mean of per-image means (frames with no
        scored error left out), the other metrics pool every scored pixel of the group. When
        there are several groups, ``"(all)"`` pools them all.
    """
    key = group_key if group_key is not None else (lambda g: g)
    index: dict[tuple[str, str], list[int]] = {}      # (summary group, label) -> row indices
    groups: list[str] = []
    for i, r in enumerate(rows):
        g = key(r["group"])
        if g not in groups:
            groups.append(g)
        index.setdefault((g, r["method"]), []).append(i)
        index.setdefault((ALL_GROUPS, r["method"]), []).append(i)
    if len(groups) > 1:
        groups.append(ALL_GROUPS)
    thresholds = np.round(np.arange(0.0, curve_max + curve_step / 2, curve_step), 6)
    out: dict[str, Any] = {"groups": {}, "curves": {"thresholds": thresholds.tolist()}}
    for g in groups:
        out["groups"][g] = {}
        out["curves"][g] = {}
        for label in labels:
            idx = index.get((g, label))
            if not idx:
                continue
            members = sorted({rows[i]["group"] for i in idx})
            hist = np.sum([hists[(m, label)] for m in members], axis=0)
            out["groups"][g][label] = _aggregate([rows[i] for i in idx], hist)
            out["curves"][g][label] = threshold_curve(hist, thresholds).tolist()
    return out


def _f(x: float, digits: int = 2) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.{digits}f}"


def _pct(x: float) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{100 * x:.1f}"


def summary_markdown(summary: dict[str, Any], labels: Sequence[str], *,
                     title: str = "Evaluation", note: str = "") -> str:
    """Markdown tables: the paper's Table III layout (e_A per group), then details per group."""
    groups = list(summary["groups"])
    table_groups = [g for g in groups if g != ALL_GROUPS] or groups
    lines = [f"# {title}", ""]
    if note:
        lines += [note, ""]
    lines += ["## e_A (degrees, mean of per-image means) and runtime (Table III layout)", ""]
    lines.append("| Method | Runtime (ms, median) | " + " | ".join(table_groups) + " |")
    lines.append("|---|---:|" + "---:|" * len(table_groups))
    for label in labels:
        ms = [summary["groups"][g][label]["ms_median"] for g in groups
              if label in summary["groups"][g]]
        all_ms = summary["groups"].get(ALL_GROUPS, {}).get(label, {}).get("ms_median")
        ms_val = all_ms if all_ms is not None else (ms[0] if ms else float("nan"))
        cells = [_f(summary["groups"][g][label]["e_A"]) if label in summary["groups"][g] else "-"
                 for g in table_groups]
        lines.append(f"| {label} | {_f(ms_val)} | " + " | ".join(cells) + " |")
    lines.append("")
    head = ("| Method | frames | e_A | mean | median | RMSE | <5 % | <11.25 % | <22.5 % | <30 % "
            "| coverage % | near edges | smooth | near share % | ms median |")
    for g in groups:
        lines += [f"## {g}", "", head, "|---|" + "---:|" * 14]
        for label, s in summary["groups"][g].items():
            lines.append(
                f"| {label} | {s['frames']} | {_f(s['e_A'])} | {_f(s['mean'])} | "
                f"{_f(s['median'])} | {_f(s['rmse'])} | {_pct(s['a5'])} | {_pct(s['a11_25'])} | "
                f"{_pct(s['a22_5'])} | {_pct(s['a30'])} | {_pct(s['coverage'])} | "
                f"{_f(s['near_mean'])} | {_f(s['smooth_mean'])} | {_pct(s['near_share'])} | "
                f"{_f(s['ms_median'])} |")
        lines.append("")
    return "\n".join(lines)
