"""``run_evaluation``: every method on every frame, resumable, with tables, figures, sidecar."""

from __future__ import annotations

import re
import sys
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from ..datasets import Frame
from ._env import machine_description
from ._methods import MethodSpec, resolve_methods
from ._protocol import HIST_BIN_DEG, Protocol, discontinuity_mask, score_frame, scoring_mask
from ._store import PartStore, write_json, write_results_csv, write_text
from ._summary import ALL_GROUPS, group_levels_key, summarize, summary_markdown

__all__ = ["EvaluationResult", "run_evaluation"]

#: results.csv is rewritten (atomically) at most this often during a run, and at the end.
_CSV_EVERY_S = 20.0
#: Size of the crop each method is first run on, so that JIT compilation stays out of ``ms``.
_WARMUP_PX = 32
#: With more groups than this, the threshold-curve figure shows only the pooled panel.
_MAX_CURVE_PANELS = 6


@dataclass
class EvaluationResult:
    """What :func:`run_evaluation` did and wrote.

    Attributes
    ----------
    out_dir : Path
        The output folder.
    rows : list of dict
        The rows of ``results.csv`` (columns :data:`depthnormals.evaluate.FIELDS`).
    summary : dict
        The content of ``summary.json`` (per group and method; see
        :func:`depthnormals.evaluate.summarize`).
    computed, reused : int
        (frame, method) pairs estimated in this run / taken from an earlier, interrupted run.
    figures : list of Path
        PNG files written.
    settings : dict
        The content of ``settings.json``.
    """

    out_dir: Path
    rows: list[dict[str, Any]]
    summary: dict[str, Any]
    computed: int
    reused: int
    figures: list[Path] = field(default_factory=list)
    settings: dict[str, Any] = field(default_factory=dict)


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "-", text).strip("-") or "frame"


def _frames(dataset: Any, dataset_name: str | None) -> tuple[Iterator[Frame], str]:
    from .. import datasets

    if isinstance(dataset, (str, Path)):
        path = Path(dataset)
        if not path.exists():
            raise FileNotFoundError(f"dataset path {path} does not exist")
        return iter(datasets.open(path)), str(path.resolve())
    if isinstance(dataset, Frame):
        dataset = [dataset]
    if not isinstance(dataset, Iterable):
        raise TypeError(f"dataset must be a folder path or an iterable of Frame; got "
                        f"{type(dataset).__name__}")
    if not isinstance(dataset_name, str) or not dataset_name:
        raise ValueError("pass dataset_name='...' with an iterable of frames: the resumable "
                         "results are keyed on it")
    return iter(dataset), dataset_name


class _Progress:
    def __init__(self, enabled: bool, total: int | None) -> None:
        self.bar = None
        self.enabled = enabled
        self.count = 0
        if enabled:
            try:
                from tqdm import tqdm
            except ImportError:
                tqdm = None
            if tqdm is not None:
                self.bar = tqdm(total=total, desc="evaluate", unit="frame", file=sys.stderr)

    def update(self, frame: Frame, computed: int, reused: int) -> None:
        self.count += 1
        if self.bar is not None:
            self.bar.set_postfix_str(f"{frame.group}/{frame.name}", refresh=False)
            self.bar.update(1)
        elif self.enabled:
            print(f"evaluate: frame {self.count} {frame.group}/{frame.name} "
                  f"({computed} computed, {reused} reused)", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _row(frame: Frame, label: str, score: Any, ms: float) -> dict[str, Any]:
    m = score.metrics
    return {
        "group": frame.group, "frame": frame.name, "method": label,
        "mean_deg": m.mean, "median_deg": m.median, "rmse_deg": m.rmse,
        "a5": m.a5, "a11_25": m.a11_25, "a22_5": m.a22_5, "a30": m.a30,
        "coverage": m.coverage, "near_mean_deg": score.near_mean,
        "smooth_mean_deg": score.smooth_mean, "count": m.count, "scored": score.scored,
        "covered": score.covered, "near_count": score.near_count,
        "smooth_count": score.smooth_count, "ms": ms,
    }


def _accumulate(hists: dict, group: str, label: str, hist: np.ndarray) -> None:
    key = (group, label)
    if key in hists:
        hists[key] += hist
    else:
        hists[key] = hist.astype(np.int64, copy=True)


def run_evaluation(
    dataset: str | Path | Iterable[Frame],
    methods: str | Sequence[str | MethodSpec],
    out_dir: str | Path,
    *,
    folded: bool = True,
    border: int = 1,
    invalid: str = "drop",
    edge_radius: int = 2,
    edge_angle: float = 10.0,
    depth_jump: float = 0.05,
    method_options: Mapping[str, Mapping[str, Any]] | None = None,
    frames: int | None = None,
    group_levels: Sequence[int] | None = None,
    figures: int = 3,
    figure_method: str | None = None,
    error_vmax: float = 20.0,
    threads: int | None = None,
    resume: bool = True,
    progress: bool = False,
    dataset_name: str | None = None,
) -> EvaluationResult:
    """Run estimators on every frame of a dataset and write results, tables and figures.

    Writes into ``out_dir`` (every file atomically):

    - ``results.csv``: one row per (frame, method), columns :data:`depthnormals.evaluate.FIELDS`;
    - ``summary.json`` and ``summary.md``: per group and method, the paper's e_A (mean of
      per-image means), pooled metrics (every scored pixel of the group), mean error near
      discontinuities vs in smooth regions, coverage, ms per frame; the markdown starts with
      the paper's Table III layout;
    - ``figures/fig3-<group>-<frame>.png``: the paper's Fig. 3 layout for the first frame of
      up to ``figures`` groups; ``figures/threshold-curves.png``;
    - ``settings.json``: version, dataset, methods and options, protocol, machine;
    - ``parts/``: one file per finished (frame, method). An interrupted run keeps them; run
      again with the same arguments and it resumes, ending with the same results as an
      uninterrupted run (``ms`` apart).

    Parameters
    ----------
    dataset : str, Path or iterable of Frame
        A folder :func:`depthnormals.datasets.open` reads, or frames (then ``dataset_name``
        is required).
    methods : str or sequence
        Names from :func:`depthnormals.methods`, optionally with options in brackets
        (``"3f2n[aggregate=mean]"``), as a sequence or one comma-separated string; or
        :class:`MethodSpec` s. Each label must be unique.
    out_dir : str or Path
        Output folder (created if needed).
    folded : bool, default True
        Fold errors above 90 degrees (the 3F2N protocol); False scores signed angles.
    border : int, default 1
        Border width (pixels) left out of the score.
    invalid : {"drop", "score90"}, default "drop"
        NaN estimates are dropped (``coverage`` reports it) or scored as 90 degrees.
    edge_radius, edge_angle, depth_jump
        The "near a discontinuity" region, see :func:`discontinuity_mask`.
    method_options : mapping, optional
        ``{method name or label: {option: value}}``, passed to the estimators.
    frames : int, optional
        Evaluate only the first ``frames`` frames.
    group_levels : sequence of int, optional
        Summarise by these "/"-separated components of the frame groups (0-based), e.g.
        ``(0, 2)`` turns ``"indoor/room-03/clean"`` into ``"indoor/clean"`` (the paper's
        Table III columns); ``results.csv`` keeps the full group.
    figures : int, default 3
        Fig. 3 layouts for the first frame of the first ``figures`` groups (0: no figures
        at all). Figures need matplotlib (``pip install 'depthnormals[plot]'``).
    figure_method : str, optional
        Label whose estimate is panel (iii); default the last method.
    error_vmax : float, default 20.0
        Top of the error colour scale (degrees).
    threads : int, optional
        numba threads during the run (default: numba's setting, all cores).
    resume : bool, default True
        Reuse finished (frame, method) parts in ``out_dir``; False recomputes them.
    progress : bool, default False
        Progress bar on stderr (tqdm if installed, else one line per frame).
    dataset_name : str, optional
        Identifies an iterable of frames (required then).

    Returns
    -------
    EvaluationResult

    Notes
    -----
    ``ms`` is the wall time of :func:`depthnormals.estimate_normals` on the frame; each
    method first runs once on a 32 x 32 crop, so numba compilation is not counted.

    Examples
    --------
    >>> res = run_evaluation("../shared/data/3f2n-torusknot", "3f2n,d2nt",
    ...                      "out/torusknot")  # doctest: +SKIP
    >>> round(res.summary["groups"]["3f2n-torusknot"]["d2nt"]["e_A"], 4)  # doctest: +SKIP
    1.4609
    """
    from .. import __version__
    from ..registry import estimate_normals

    specs = resolve_methods(methods, method_options)
    labels = [s.label for s in specs]
    protocol = Protocol(folded=folded, border=border, invalid=invalid, edge_radius=edge_radius,
                        edge_angle=edge_angle, depth_jump=depth_jump)
    if frames is not None and (isinstance(frames, bool) or not isinstance(frames, int)
                               or frames < 1):
        raise ValueError(f"frames must be a positive integer or None; got {frames!r}")
    if isinstance(figures, bool) or not isinstance(figures, int) or figures < 0:
        raise ValueError(f"figures must be an integer >= 0; got {figures!r}")
    group_key = None if group_levels is None else group_levels_key(group_levels)
    fig_label = labels[-1] if figure_method is None else figure_method
    if fig_label not in labels:
        raise ValueError(f"figure_method {figure_method!r} is not among the methods {labels}")
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int)
                                or threads < 1):
        raise ValueError(f"threads must be a positive integer or None; got {threads!r}")
    if figures:
        from ._figures import plot_fig3, plot_threshold_curves, require_matplotlib

        require_matplotlib()
    frame_iter, dataset_id = _frames(dataset, dataset_name)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fig_dir = out / "figures"
    if figures:
        fig_dir.mkdir(exist_ok=True)

    import numba

    old_threads = numba.get_num_threads()
    if threads is not None:
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    settings: dict[str, Any] = {
        "tool": "depthnormals evaluate",
        "version": __version__,
        "started": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "completed": False,
        "dataset": {"id": dataset_id, "frames_limit": frames,
                    "group_levels": None if group_levels is None else list(group_levels)},
        "methods": [s.as_dict() for s in specs],
        "protocol": {**protocol.as_dict(), "pixels": "ground truth valid and inside the "
                     "dataset mask, minus the border",
                     "e_A": "mean over frames of the per-frame mean error",
                     "pooled": "every scored pixel of the group counted once",
                     "histogram_bin_deg": HIST_BIN_DEG},
        "timing": {"clock": "time.perf_counter around estimate_normals, per frame",
                   "warmup": f"each method first runs on a {_WARMUP_PX}x{_WARMUP_PX} crop",
                   "numba_threads": int(numba.get_num_threads())},
        "figures": {"count": figures, "figure_method": fig_label, "error_vmax": error_vmax},
        "machine": machine_description(),
    }
    write_json(out / "settings.json", settings)

    store = PartStore(out / "parts")
    rows: list[dict[str, Any]] = []
    # error histograms summed per (group, label): memory independent of the frame count
    hists: dict[tuple[str, str], np.ndarray] = {}
    seen: set[tuple[str, str]] = set()
    fig_groups: set[str] = set()
    written: list[Path] = []
    warmed: set[str] = set()
    computed = reused = 0
    bar = _Progress(progress, frames)
    last_csv = time.monotonic()
    try:
        for i, frame in enumerate(frame_iter):
            if frames is not None and i >= frames:
                break
            if not isinstance(frame, Frame):
                raise TypeError(f"dataset yielded {type(frame).__name__}; expected Frame")
            ident = (frame.group, frame.name)
            if ident in seen:
                raise ValueError(f"frame {frame.group}/{frame.name} appears twice in the dataset")
            seen.add(ident)
            want_fig = bool(figures) and frame.group not in fig_groups and \
                len(fig_groups) < figures
            near = None
            fig_errors: dict[str, np.ndarray] = {}
            fig_estimate = None
            for spec in specs:
                key = store.key(dataset=dataset_id, group=frame.group, frame=frame.name,
                                method=spec.method, options=spec.options,
                                protocol=protocol.as_dict())
                got = store.load(key) if resume else None
                if got is not None and not want_fig:
                    row, hist = got
                    row.update(group=frame.group, frame=frame.name, method=spec.label)
                    rows.append(row)
                    _accumulate(hists, frame.group, spec.label, hist)
                    reused += 1
                    continue
                if spec.label not in warmed:
                    crop = np.ascontiguousarray(frame.depth[:_WARMUP_PX, :_WARMUP_PX])
                    estimate_normals(crop, frame.K, method=spec.method, **spec.options)
                    warmed.add(spec.label)
                t0 = time.perf_counter()
                est = estimate_normals(frame.depth, frame.K, method=spec.method, **spec.options)
                ms = (time.perf_counter() - t0) * 1e3
                if near is None:
                    near = discontinuity_mask(frame.normals, frame.depth, frame.mask,
                                              radius=protocol.edge_radius,
                                              edge_angle=protocol.edge_angle,
                                              depth_jump=protocol.depth_jump)
                score = score_frame(est, frame.normals, mask=frame.mask, near=near,
                                    protocol=protocol)
                if want_fig:
                    fig_errors[spec.label] = score.error
                    if spec.label == fig_label:
                        fig_estimate = est
                if got is not None:
                    row, hist = got
                    row.update(group=frame.group, frame=frame.name, method=spec.label)
                    reused += 1
                else:
                    row, hist = _row(frame, spec.label, score, ms), score.hist
                    store.save(key, row, hist)
                    computed += 1
                rows.append(row)
                _accumulate(hists, frame.group, spec.label, hist)
            if want_fig:
                fig_groups.add(frame.group)
                path = fig_dir / f"fig3-{_safe(frame.group)}-{_safe(frame.name)}.png"
                plot_fig3(path, frame.depth, frame.normals,
                          scoring_mask(frame.normals, frame.mask, border=protocol.border),
                          fig_estimate, fig_label, fig_errors,
                          title=f"{frame.group} / {frame.name}", vmax=error_vmax)
                written.append(path)
            bar.update(frame, computed, reused)
            if time.monotonic() - last_csv > _CSV_EVERY_S:
                write_results_csv(out / "results.csv", rows)
                last_csv = time.monotonic()
    finally:
        bar.close()
        if threads is not None:
            numba.set_num_threads(old_threads)
        write_results_csv(out / "results.csv", rows)
    if not rows:
        raise ValueError(f"the dataset {dataset_id} yielded no frames")

    summary = summarize(rows, hists, labels, group_key=group_key)
    summary = {"settings": {k: settings[k] for k in ("version", "dataset", "methods",
                                                     "protocol")}, **summary}
    write_json(out / "summary.json", summary)
    note = (f"Dataset `{dataset_id}`; protocol: {'folded' if folded else 'signed'} errors, "
            f"{border}-pixel border, invalid estimates "
            f"{'dropped' if invalid == 'drop' else 'scored 90 deg'}; near edges = within "
            f"{edge_radius} px of a ground-truth crease (> {edge_angle} deg) or depth jump "
            f"(> {100 * depth_jump:g} %) or silhouette.")
    write_text(out / "summary.md", summary_markdown(summary, labels, note=note) + "\n")
    if figures:
        curves = summary["curves"]
        groups = [g for g in summary["groups"]]
        if len(groups) > _MAX_CURVE_PANELS and ALL_GROUPS in groups:
            groups = [ALL_GROUPS]
        path = fig_dir / "threshold-curves.png"
        plot_threshold_curves(path, curves["thresholds"], {g: curves[g] for g in groups},
                              title="Share of pixels with angular error below t")
        written.append(path)
    settings["completed"] = True
    settings["finished"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
    settings["counts"] = {"frames": len(seen), "rows": len(rows), "computed": computed,
                          "reused": reused}
    write_json(out / "settings.json", settings)
    return EvaluationResult(out, rows, summary, computed, reused, written, settings)

