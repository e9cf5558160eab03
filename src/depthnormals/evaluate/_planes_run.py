"""``run_plane_evaluation``: every method on every frame of a dataset, scored on its planes.

The front end of the plane reference (:mod:`._planes`) for datasets without ground-truth
normals (real sensor folders): per frame, the plane reference once, then each method's
estimate scored on the plane interiors and rims and in the bands by the planes' creases
(:mod:`._creases`). Writes ``planes.json`` (per frame and plane, and the summary per group and
method), ``planes.md`` (the table) and one figure per frame.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from .._progress import Progress
from ._creases import CreaseBand, crease_band, score_creases
from ._env import machine_description
from ._methods import MethodSpec, resolve_methods
from ._planes import PlaneReference, plane_reference, score_planes, sensor_threshold
from ._run import _estimate, _frames, _safe
from ._store import write_json, write_text

__all__ = ["PlaneEvaluationResult", "plane_summary", "plane_table_markdown",
           "run_plane_evaluation"]

#: The group of the summary that pools every frame.
ALL = "(all)"
_KEYS = ("interior_mean", "rim_mean", "interior_median", "rim_median", "coverage",
         "crease_mean", "crease_near_mean", "crease_far_mean")


@dataclass
class PlaneEvaluationResult:
    """What :func:`run_plane_evaluation` did and wrote.

    Attributes
    ----------
    out_dir : Path
        The output folder.
    frames : list of dict
        Per frame: ``group``, ``frame``, ``planes`` (the reference's :class:`PlaneInfo` as
        dicts), ``creases`` (the crease band's pairs and pixels), ``settings`` (of the
        reference) and ``scores`` (method label -> the dict of :func:`score_planes` plus
        ``crease_mean``, ``crease_near_mean``, ``crease_far_mean``, ``n_crease`` and
        ``scored_crease`` of :func:`score_creases`, and ``ms``).
    summary : dict
        group -> method -> the means over frames (see :func:`plane_summary`).
    table : str
        The markdown table (``planes.md``).
    figures : list of Path
        PNG files written.
    settings : dict
        Version, dataset, methods, seed, threads, machine, times.
    """

    out_dir: Path
    frames: list[dict[str, Any]]
    summary: dict[str, Any]
    table: str
    figures: list[Path] = field(default_factory=list)
    settings: dict[str, Any] = field(default_factory=dict)


def plane_summary(frames: Sequence[Mapping[str, Any]], labels: Sequence[str]
                  ) -> dict[str, dict[str, dict[str, Any]]]:
    """Per group (and ``"(all)"``) and method: the mean over frames of each frame's
    ``interior_mean``, ``rim_mean``, ``interior_median``, ``rim_median``, ``coverage`` and
    crease-band means ``crease_mean``, ``crease_near_mean``, ``crease_far_mean`` (frames where
    a value is NaN, e.g. without a crease, are left out of its mean), the pooled interior, rim
    and crease means (every scored pixel once: ``pooled_interior_mean``, ``pooled_rim_mean``,
    ``pooled_crease_mean``), ``frames`` and ``planes`` counted, and the median ``ms``."""
    groups: dict[str, list[Mapping[str, Any]]] = {}
    for f in frames:
        groups.setdefault(f["group"], []).append(f)
    groups[ALL] = list(frames)
    out: dict[str, dict[str, dict[str, Any]]] = {}
    for g, fs in groups.items():
        out[g] = {}
        for label in labels:
            scores = [f["scores"][label] for f in fs if label in f["scores"]]
            entry: dict[str, Any] = {"frames": len(scores),
                                     "planes": int(sum(s["n_planes"] for s in scores))}
            for key in _KEYS:
                vals = [s[key] for s in scores if np.isfinite(s[key])]
                entry[key] = float(np.mean(vals)) if vals else float("nan")
            for part in ("interior", "rim", "crease"):
                n = sum(s[f"scored_{part}"] for s in scores)
                tot = sum(s[f"{part}_mean"] * s[f"scored_{part}"] for s in scores
                          if s[f"scored_{part}"])
                entry[f"pooled_{part}_mean"] = tot / n if n else float("nan")
            ms = [s["ms"] for s in scores]
            entry["ms_median"] = float(np.median(ms)) if ms else float("nan")
            out[g][label] = entry
    return out


def _cell(x: float, digits: int = 2) -> str:
    return "-" if not np.isfinite(x) else f"{x:.{digits}f}"


def plane_table_markdown(summary: Mapping[str, Mapping[str, Mapping[str, Any]]],
                         labels: Sequence[str]) -> str:
    """The table: one row per (group, method) with the interior, rim and crease-band means
    (deg), the coverage (%) and the median ms; the groups in order, ``(all)`` last."""
    lines = ["| group | method | interior (deg) | rim (deg) | crease (deg) | interior median "
             "| rim median | coverage (%) | planes | ms |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for g, per in summary.items():
        for label in labels:
            e = per[label]
            lines.append(f"| {g} | {label} | {_cell(e['interior_mean'])} | {_cell(e['rim_mean'])} "
                         f"| {_cell(e['crease_mean'])} "
                         f"| {_cell(e['interior_median'])} | {_cell(e['rim_median'])} "
                         f"| {_cell(100 * e['coverage'], 1)} | {e['planes']} "
                         f"| {_cell(e['ms_median'], 1)} |")
    return "\n".join(lines) + "\n"


def _frame_entry(frame: Any, ref: PlaneReference, band: CreaseBand) -> dict[str, Any]:
    return {"group": frame.group, "frame": frame.name,
            "planes": [vars(p) | {"normal": list(p.normal)} for p in ref.planes],
            "creases": {"pixels": int(band.mask.sum()), "pairs": list(band.pairs)},
            "settings": ref.settings, "scores": {}}


def _score_frame(frame: Any, specs: Sequence[MethodSpec], ref: PlaneReference, band: CreaseBand,
                 warmed: set[str]) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    from ..metrics import angular_error

    scores, errors = {}, {}
    truth = ref.normal_map()
    truth[band.mask] = band.normals[band.mask]
    for spec in specs:
        est, ms = _estimate(spec, frame, warmed)
        s = score_planes(est, ref)
        c = score_creases(est, band)
        s.update({"crease_mean": c["mean"], "crease_near_mean": c["near_mean"],
                  "crease_far_mean": c["far_mean"], "n_crease": c["n"],
                  "scored_crease": c["scored"]})
        s["ms"] = ms
        scores[spec.label] = s
        errors[spec.label] = angular_error(est, truth)
    return scores, errors


def run_plane_evaluation(dataset: Any, methods: str | Sequence[str | MethodSpec],
                         out: str | Path, *,
                         method_options: Mapping[str, Mapping[str, Any]] | None = None,
                         frames: int | None = None, figures: bool = True, seed: int = 0,
                         threshold: tuple[float, float] | None = None, consensus: int = 3,
                         threads: int | None = None, progress: bool = False,
                         dataset_name: str | None = None) -> PlaneEvaluationResult:
    """Score methods on the plane reference of every frame of a dataset (no ground truth).

    Per frame: :func:`plane_reference` (``seed``; the threshold from
    :func:`sensor_threshold` unless ``threshold`` is given), then each method's estimate
    (:func:`depthnormals.estimate_normals`, compilation kept out of ``ms`` as in
    :func:`run_evaluation`) scored by :func:`score_planes` (signed errors: the reference
    faces the camera) and in the frame's crease bands by :func:`score_creases`
    (:func:`crease_band`). docs/evaluation.md, section "Real sensors without ground truth".

    Parameters
    ----------
    dataset : str, Path or iterable of Frame
        Anything :func:`depthnormals.datasets.open` reads (e.g. a real sensor folder, or a
        folder of them), or frames (then ``dataset_name`` is required).
    methods : str or sequence
        Method specs, as for :func:`run_evaluation` (``"3f2n+,fals[window=11]"``).
    out : str or Path
        Output folder: ``planes.json``, ``planes.md``, ``figures/planes-<group>-<frame>.png``.
    method_options : mapping, optional
        Extra options per method name or label.
    frames : int, optional
        Only the first N frames.
    figures : bool, default True
        Draw one figure per frame (needs matplotlib).
    seed : int, default 0
        Seed of the plane reference's RANSAC.
    threshold : (float, float), optional
        Inlier threshold of every frame's reference (default: per frame, from its sensor).
    consensus : int, default 3
        Runs of the plane search that must agree (:func:`plane_reference`).
    threads : int, optional
        Threads of the estimators during the run (restored afterwards).
    progress : bool, default False
        Show a progress report.
    dataset_name : str, optional
        Name recorded for an iterable of frames.

    Returns
    -------
    PlaneEvaluationResult
    """
    from .. import __version__
    from .._parallel import get_num_threads, set_num_threads

    specs = resolve_methods(methods, method_options)
    labels = [s.label for s in specs]
    if frames is not None and (isinstance(frames, bool) or not isinstance(frames, int) or frames < 1):
        raise ValueError(f"frames must be a positive integer or None; got {frames!r}")
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int)
                                or threads < 1):
        raise ValueError(f"threads must be a positive integer or None; got {threads!r}")
    if figures:
        from ._figures import require_matplotlib

        require_matplotlib()
    frame_iter, dataset_id = _frames(dataset, dataset_name)
    out_dir = Path(out)
    out_dir.mkdir(parents=True, exist_ok=True)
    old = get_num_threads()
    if threads is not None:
        set_num_threads(threads)
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")
    entries: list[dict[str, Any]] = []
    drawn: list[Path] = []
    warmed: set[str] = set()
    bar = Progress("evaluate planes", unit="frame", enabled=progress)
    try:
        for i, frame in enumerate(frame_iter):
            if frames is not None and i >= frames:
                break
            thr = threshold if threshold is not None else sensor_threshold(frame.meta)
            ref = plane_reference(frame.depth, frame.K, seed=seed, threshold=thr,
                                  consensus=consensus)
            band = crease_band(frame.depth, frame.K, ref)
            entry = _frame_entry(frame, ref, band)
            entry["scores"], errors = _score_frame(frame, specs, ref, band, warmed)
            entries.append(entry)
            if figures:
                from ._planes_figures import plot_planes

                path = out_dir / "figures" / f"planes-{_safe(frame.group)}-{_safe(frame.name)}.png"
                path.parent.mkdir(parents=True, exist_ok=True)
                plot_planes(path, frame.depth, ref, errors=errors, band=band,
                            title=f"{frame.group} / {frame.name}")
                drawn.append(path)
            bar.update(f"{frame.group}/{frame.name}: {ref.n_planes} planes")
    finally:
        bar.close()
        used = get_num_threads()
        set_num_threads(old)
    summary = plane_summary(entries, labels)
    table = plane_table_markdown(summary, labels)
    settings = {"version": __version__, "dataset": dataset_id, "reference": "planes",
                "methods": [{"label": s.label, "method": s.method, "options": s.options}
                            for s in specs],
                "seed": seed, "consensus": consensus,
                "threshold": None if threshold is None else list(threshold),
                "errors": "signed", "threads": used, "machine": machine_description(),
                "started": started,
                "finished": datetime.now(timezone.utc).isoformat(timespec="seconds")}
    write_json(out_dir / "planes.json", {"settings": settings, "summary": summary,
                                         "frames": entries})
    write_text(out_dir / "planes.md", "# Plane reference: interior / rim / crease-band errors\n\n"
               + table)
    return PlaneEvaluationResult(out_dir=out_dir, frames=entries, summary=summary, table=table,
                                 figures=drawn, settings=settings)
