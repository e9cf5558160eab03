"""``run_evaluation``: every method on every frame, resumable, with tables, figures, sidecar.

The run is three pieces: :func:`plan_evaluation` checks the arguments into an
:class:`EvaluationPlan`; ``_evaluate_frame`` estimates and scores every method on one frame
(reusing what an interrupted run finished) and draws its Fig. 3 layout; ``_write_summary``
turns the rows and error histograms into the tables and the threshold curves.
"""

from __future__ import annotations

import re
import time
import warnings
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from .._fingerprint import array_digest, code_fingerprint
from .._progress import Progress
from .._validate import NoValidNormalWarning, check_positive
from ..datasets import Frame
from ._env import machine_description
from ._methods import MethodSpec, resolve_methods
from ._protocol import HIST_BIN_DEG, Protocol, discontinuity_mask, score_frame, scoring_mask
from ._store import PartStore, write_json, write_results_csv, write_text
from ._summary import ALL_GROUPS, check_group_levels, group_levels_key, summarize, summary_markdown

__all__ = ["EvaluationPlan", "EvaluationResult", "plan_evaluation", "run_evaluation"]

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



# --------------------------------------------------------------------------------- the plan

@dataclass(frozen=True)
class EvaluationPlan:
    """What an evaluation computes, scores and draws: checked arguments of :func:`run_evaluation`.

    Build one with :func:`plan_evaluation`; every field is validated there.

    Attributes
    ----------
    methods : tuple of MethodSpec
        The methods, each with a unique label.
    protocol : Protocol
        Which pixels are scored and how.
    frames : int or None
        Evaluate only the first ``frames`` frames.
    group_levels : tuple of int or None
        Components of the group names the summary keeps (see :func:`group_levels_key`).
    figures : int
        Fig. 3 layouts for the first frame of up to this many groups (0: no figures).
    figure_label : str
        Label whose estimate is panel (iii).
    error_vmax : float
        Top of the error colour scale (degrees).
    threads : int or None
        Threads of the estimators during the run (:func:`depthnormals.set_num_threads`);
        None keeps the current setting.
    """

    methods: tuple[MethodSpec, ...]
    protocol: Protocol
    frames: int | None
    group_levels: tuple[int, ...] | None
    figures: int
    figure_label: str
    error_vmax: float
    threads: int | None

    @property
    def labels(self) -> list[str]:
        """The method labels, in order."""
        return [s.label for s in self.methods]


def plan_evaluation(
    methods: str | Sequence[str | MethodSpec],
    *,
    protocol: Protocol | None = None,
    method_options: Mapping[str, Mapping[str, Any]] | None = None,
    frames: int | None = None,
    group_levels: Sequence[int] | None = None,
    figures: int = 3,
    figure_method: str | None = None,
    error_vmax: float = 20.0,
    threads: int | None = None,
) -> EvaluationPlan:
    """Check the arguments of an evaluation and return them as an :class:`EvaluationPlan`.

    Nothing is read or written. The parameters are those of :func:`run_evaluation` (the
    dataset, output folder and run options apart).

    Returns
    -------
    EvaluationPlan

    Raises
    ------
    ValueError, TypeError
        Naming the argument that is wrong and what it accepts.

    Examples
    --------
    >>> plan = plan_evaluation("3f2n,d2nt[variant=basic]", threads=1)
    >>> plan.labels, plan.figure_label, plan.protocol.border
    (['3f2n', 'd2nt[variant=basic]'], 'd2nt[variant=basic]', 1)
    """
    specs = tuple(resolve_methods(methods, method_options))
    labels = [s.label for s in specs]
    if protocol is None:
        protocol = Protocol()
    elif not isinstance(protocol, Protocol):
        raise TypeError(f"protocol must be a depthnormals.evaluate.Protocol; got "
                        f"{type(protocol).__name__}")
    if frames is not None and (isinstance(frames, bool) or not isinstance(frames, int)
                               or frames < 1):
        raise ValueError(f"frames must be a positive integer or None; got {frames!r}")
    if isinstance(figures, bool) or not isinstance(figures, int) or figures < 0:
        raise ValueError(f"figures must be an integer >= 0; got {figures!r}")
    if group_levels is not None:
        group_levels_key(group_levels)  # raises on an empty or non-integer list
        group_levels = tuple(int(i) for i in group_levels)
    fig_label = labels[-1] if figure_method is None else figure_method
    if fig_label not in labels:
        raise ValueError(f"figure_method {figure_method!r} is not among the methods {labels}")
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int)
                                or threads < 1):
        raise ValueError(f"threads must be a positive integer or None; got {threads!r}")
    error_vmax = check_positive(error_vmax, "error_vmax")
    return EvaluationPlan(specs, protocol, frames, group_levels, figures, fig_label,
                          error_vmax, threads)


def _settings(plan: EvaluationPlan, dataset_id: str) -> dict[str, Any]:
    """settings.json at the start of a run; ``threads`` is what the estimators really use."""
    from .. import __version__
    from .._parallel import get_num_threads

    return {
        "tool": "depthnormals evaluate",
        "version": __version__,
        "started": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "completed": False,
        "dataset": {"id": dataset_id, "frames_limit": plan.frames,
                    "group_levels": None if plan.group_levels is None else list(plan.group_levels)},
        "methods": [s.as_dict() for s in plan.methods],
        "protocol": {**plan.protocol.as_dict(), "pixels": "ground truth valid and inside the "
                     "dataset mask, minus the border",
                     "e_A": "mean over frames of the per-frame mean error",
                     "pooled": "every scored pixel of the group counted once",
                     "histogram_bin_deg": HIST_BIN_DEG},
        "timing": {"clock": "time.perf_counter around estimate_normals, per frame",
                   "warmup": f"each method first runs on a {_WARMUP_PX}x{_WARMUP_PX} crop",
                   "threads": get_num_threads()},
        "figures": {"count": plan.figures, "figure_method": plan.figure_label,
                    "error_vmax": plan.error_vmax},
        "machine": machine_description(),
    }


# ---------------------------------------------------------------------------- per frame

@dataclass
class _Tally:
    """What the frames have produced so far."""

    rows: list[dict[str, Any]] = field(default_factory=list)
    # error histograms summed per (group, label): memory independent of the frame count
    hists: dict[tuple[str, str], np.ndarray] = field(default_factory=dict)
    seen: set[tuple[str, str]] = field(default_factory=set)
    fig_groups: set[str] = field(default_factory=set)
    figures: list[Path] = field(default_factory=list)
    warmed: set[str] = field(default_factory=set)
    computed: int = 0
    reused: int = 0

    def add(self, frame: Frame, label: str, row: dict[str, Any], hist: np.ndarray) -> None:
        self.rows.append(row)
        key = (frame.group, label)
        if key in self.hists:
            self.hists[key] += hist
        else:
            self.hists[key] = hist.astype(np.int64, copy=True)


def _estimate(spec: MethodSpec, frame: Frame, warmed: set[str]) -> tuple[np.ndarray, float]:
    """The estimate of one method on one frame and its wall time in ms (compilation excluded:
    a method not in ``warmed`` first runs on a small crop, then joins it)."""
    from ..registry import estimate_normals

    if spec.label not in warmed:
        crop = np.ascontiguousarray(frame.depth[:_WARMUP_PX, :_WARMUP_PX])
        with warnings.catch_warnings():  # the corner may hold no valid depth (KITTI): not news
            warnings.simplefilter("ignore", NoValidNormalWarning)
            estimate_normals(crop, frame.K, method=spec.method, **spec.options)
        warmed.add(spec.label)
    t0 = time.perf_counter()
    est = estimate_normals(frame.depth, frame.K, method=spec.method, **spec.options)
    return est, (time.perf_counter() - t0) * 1e3


def _part_keys(store: PartStore, dataset_id: str, frame: Frame, specs: Sequence[MethodSpec],
               protocol: Protocol) -> list[str]:
    """The store keys of a frame's (frame, method) parts, one per spec (the serial and the
    Dask runs share them): the frame's name and its data (depth, ground truth, mask, camera: a
    frame rewritten under the same name is scored again; digested once for all the methods),
    the method, the protocol and the library's code (an edited library scores again; its
    version string does not change between development builds)."""
    data = array_digest(frame.depth, frame.normals, frame.mask, frame.K)
    return [store.key(dataset=dataset_id, group=frame.group, frame=frame.name, data=data,
                      code=code_fingerprint(), method=spec.method, options=spec.options,
                      protocol=protocol.as_dict()) for spec in specs]


def _near_mask(frame: Frame, protocol: Protocol) -> np.ndarray:
    """The frame's near-discontinuity band under ``protocol``."""
    return discontinuity_mask(frame.normals, frame.depth, frame.mask, radius=protocol.edge_radius,
                              edge_angle=protocol.edge_angle, depth_jump=protocol.depth_jump)


def _evaluate_frame(frame: Frame, plan: EvaluationPlan, store: PartStore, dataset_id: str,
                    tally: _Tally, *, resume: bool, fig_dir: Path) -> None:
    """Every method on one frame: reuse a finished part or estimate, score and save it."""
    if not isinstance(frame, Frame):
        raise TypeError(f"dataset yielded {type(frame).__name__}; expected Frame")
    ident = (frame.group, frame.name)
    if ident in tally.seen:
        raise ValueError(f"frame {frame.group}/{frame.name} appears twice in the dataset")
    tally.seen.add(ident)
    protocol = plan.protocol
    want_fig = bool(plan.figures) and frame.group not in tally.fig_groups and \
        len(tally.fig_groups) < plan.figures
    near = None
    fig_errors: dict[str, np.ndarray] = {}
    fig_estimate = None
    keys = _part_keys(store, dataset_id, frame, plan.methods, protocol)
    for spec, key in zip(plan.methods, keys, strict=True):
        got = store.load(key) if resume else None
        if got is None or want_fig:
            est, ms = _estimate(spec, frame, tally.warmed)
            if near is None:
                near = _near_mask(frame, protocol)
            score = score_frame(est, frame.normals, mask=frame.mask, near=near, protocol=protocol)
            if want_fig:
                fig_errors[spec.label] = score.error
                if spec.label == plan.figure_label:
                    fig_estimate = est
        if got is not None:
            row, hist = got
            row.update(group=frame.group, frame=frame.name, method=spec.label)
            tally.reused += 1
        else:
            row, hist = _row(frame, spec.label, score, ms), score.hist
            store.save(key, row, hist)
            tally.computed += 1
        tally.add(frame, spec.label, row, hist)
    if want_fig:
        tally.fig_groups.add(frame.group)
        tally.figures.append(_draw_fig3(frame, plan, fig_estimate, fig_errors, fig_dir))


def _draw_fig3(frame: Frame, plan: EvaluationPlan, estimate: np.ndarray,
               errors: dict[str, np.ndarray], fig_dir: Path) -> Path:
    """The paper's Fig. 3 layout for one frame."""
    from ._figures import plot_fig3

    path = fig_dir / f"fig3-{_safe(frame.group)}-{_safe(frame.name)}.png"
    plot_fig3(path, frame.depth, frame.normals,
              scoring_mask(frame.normals, frame.mask, border=plan.protocol.border),
              estimate, plan.figure_label, errors,
              title=f"{frame.group} / {frame.name}", vmax=plan.error_vmax)
    return path


# ------------------------------------------------------------------------------ summary

def _write_summary(plan: EvaluationPlan, tally: _Tally, settings: dict[str, Any], out: Path,
                   fig_dir: Path) -> dict[str, Any]:
    """summary.json, summary.md and the threshold-curve figure from the rows and histograms."""
    labels = plan.labels
    group_key = None if plan.group_levels is None else group_levels_key(plan.group_levels)
    summary = summarize(tally.rows, tally.hists, labels, group_key=group_key)
    summary = {"settings": {k: settings[k] for k in ("version", "dataset", "methods",
                                                     "protocol")}, **summary}
    write_json(out / "summary.json", summary)
    p = plan.protocol
    note = (f"Dataset `{settings['dataset']['id']}`; protocol: "
            f"{'folded' if p.folded else 'signed'} errors, "
            f"{p.border}-pixel border, invalid estimates "
            f"{'dropped' if p.invalid == 'drop' else 'scored 90 deg'}; near edges = within "
            f"{p.edge_radius} px of a ground-truth crease (> {p.edge_angle} deg) or depth jump "
            f"(> {100 * p.depth_jump:g} %) or silhouette.")
    write_text(out / "summary.md", summary_markdown(summary, labels, note=note) + "\n")
    if plan.figures:
        from ._figures import plot_threshold_curves

        curves = summary["curves"]
        groups = list(summary["groups"])
        if len(groups) > _MAX_CURVE_PANELS and ALL_GROUPS in groups:
            groups = [ALL_GROUPS]
        path = fig_dir / "threshold-curves.png"
        plot_threshold_curves(path, curves["thresholds"], {g: curves[g] for g in groups},
                              title="Share of pixels with angular error below t")
        tally.figures.append(path)
    return summary


# ---------------------------------------------------------------------------- the run

_PROTOCOL_FIELDS = ("folded", "border", "invalid", "edge_radius", "edge_angle", "depth_jump")


def run_evaluation(
    dataset: str | Path | Iterable[Frame],
    methods: str | Sequence[str | MethodSpec],
    out_dir: str | Path,
    *,
    protocol: Protocol | None = None,
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
    **moved: Any,
) -> EvaluationResult:
    """Run estimators on every frame of a dataset and write results, tables and figures.

    Three pieces, in order: the plan (:func:`plan_evaluation` checks every argument before
    anything is written), the frames (each method estimated and scored on each frame, or
    reused from an interrupted run; the Fig. 3 layout drawn for the first frame of a group),
    the summary (tables and threshold curves from the rows and the error histograms).

    Writes into ``out_dir`` (every file atomically):

    - ``results.csv``: one row per (frame, method), columns :data:`depthnormals.evaluate.FIELDS`;
    - ``summary.json`` and ``summary.md``: per group and method, the paper's e_A (mean of
      per-image means), pooled metrics (every scored pixel of the group), mean error near
      discontinuities vs in smooth regions, coverage, ms per frame; the markdown starts with
      the paper's Table III layout;
    - ``figures/fig3-<group>-<frame>.png``: the paper's Fig. 3 layout for the first frame of
      up to ``figures`` groups; ``figures/threshold-curves.png``;
    - ``settings.json``: version, dataset, methods and options, protocol, threads, machine;
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
    protocol : Protocol, optional
        Which pixels are scored and how (default ``Protocol()``: folded errors, 1-pixel
        border, NaN estimates dropped, the "near a discontinuity" region of
        :func:`discontinuity_mask`).
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
        at all). Figures need matplotlib (``pip install 'depthnormals[plot]'``): without it
        this raises ImportError (the ``depthnormals evaluate`` command skips them instead).
    figure_method : str, optional
        Label whose estimate is panel (iii); default the last method.
    error_vmax : float, default 20.0
        Top of the error colour scale (degrees).
    threads : int, optional
        Threads of the estimators during the run (:func:`depthnormals.set_num_threads`,
        restored afterwards; default: the current setting, all cores unless changed).
        settings.json records the count used.
    resume : bool, default True
        Reuse finished (frame, method) parts in ``out_dir``; False recomputes them.
    progress : bool, default False
        Progress on stderr: a tqdm bar on a terminal (if tqdm is installed), else one line
        per frame.
    dataset_name : str, optional
        Identifies an iterable of frames (required then).

    Returns
    -------
    EvaluationResult

    Raises
    ------
    TypeError
        For ``folded=``, ``border=``, ``invalid=``, ``edge_radius=``, ``edge_angle=`` or
        ``depth_jump=``: these moved into ``protocol=Protocol(...)``.

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
    if moved:
        _reject_moved(moved)
    plan = plan_evaluation(methods, protocol=protocol, method_options=method_options,
                           frames=frames, group_levels=group_levels, figures=figures,
                           figure_method=figure_method, error_vmax=error_vmax, threads=threads)
    if plan.figures:
        from ._figures import require_matplotlib

        require_matplotlib()
    frame_iter, dataset_id = _frames(dataset, dataset_name)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fig_dir = out / "figures"
    if plan.figures:
        fig_dir.mkdir(exist_ok=True)

    from .._parallel import get_num_threads, set_num_threads

    old_threads = get_num_threads()
    if plan.threads is not None:
        set_num_threads(plan.threads)
    try:
        settings = _settings(plan, dataset_id)
        write_json(out / "settings.json", settings)
        tally = _run_frames(frame_iter, plan, dataset_id, out, fig_dir, resume=resume,
                            progress=progress)
    finally:
        if plan.threads is not None:
            set_num_threads(old_threads)
    if not tally.rows:
        raise ValueError(f"the dataset {dataset_id} yielded no frames")
    summary = _write_summary(plan, tally, settings, out, fig_dir)
    settings["completed"] = True
    settings["finished"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
    settings["counts"] = {"frames": len(tally.seen), "rows": len(tally.rows),
                          "computed": tally.computed, "reused": tally.reused}
    write_json(out / "settings.json", settings)
    return EvaluationResult(out, tally.rows, summary, tally.computed, tally.reused,
                            tally.figures, settings)


def _run_frames(frame_iter: Iterator[Frame], plan: EvaluationPlan, dataset_id: str, out: Path,
                fig_dir: Path, *, resume: bool, progress: bool) -> _Tally:
    """The frame loop: results.csv rewritten every ``_CSV_EVERY_S`` and at the end, even on error."""
    store = PartStore(out / "parts")
    tally = _Tally()
    bar = Progress("evaluate", total=plan.frames, unit="frame", enabled=progress)
    last_csv = time.monotonic()
    try:
        for i, frame in enumerate(frame_iter):
            if plan.frames is not None and i >= plan.frames:
                break
            if plan.group_levels is not None:  # fail at the frame, not after the run
                check_group_levels(plan.group_levels, frame.group)
            _evaluate_frame(frame, plan, store, dataset_id, tally, resume=resume, fig_dir=fig_dir)
            bar.update(f"{frame.group}/{frame.name}",
                       line=f"evaluate: frame {bar.count + 1} {frame.group}/{frame.name} "
                            f"({tally.computed} computed, {tally.reused} reused)")
            if time.monotonic() - last_csv > _CSV_EVERY_S:
                write_results_csv(out / "results.csv", tally.rows)
                last_csv = time.monotonic()
    finally:
        bar.close()
        write_results_csv(out / "results.csv", tally.rows)
    return tally


def _reject_moved(moved: Mapping[str, Any]) -> None:
    """TypeError for keywords that are not parameters, naming the new spelling where one exists."""
    old = [k for k in moved if k in _PROTOCOL_FIELDS]
    if old:
        spelled = ", ".join(f"{k}={moved[k]!r}" for k in old)
        raise TypeError(f"run_evaluation() no longer takes {', '.join(old)}: pass "
                        f"protocol=Protocol({spelled}) (depthnormals.evaluate.Protocol)")
    raise TypeError(f"run_evaluation() got unexpected keyword argument(s) {sorted(moved)}")
