"""Evaluation harness: the paper's tables and figures for any dataset this library reads.

:func:`run_evaluation` runs estimators on every frame and writes ``results.csv`` (one row
per frame and method), per-group summaries (markdown and JSON), figures and a sidecar JSON
of its settings; an interrupted run resumes. :func:`plan_evaluation` checks its arguments
into an :class:`EvaluationPlan` without running anything. The pieces are public too: :class:`Protocol`
(which pixels count and how), :func:`score_frame`, :func:`discontinuity_mask`,
:func:`summarize`, :func:`discontinuity_share` (how much of a frame lies near an edge).
Real sensor frames without ground truth are scored on their large planes:
:func:`plane_reference` finds them, :func:`score_planes` scores an estimate on their interiors
and rims, :func:`run_plane_evaluation` does both for every frame and method of a dataset;
:func:`crease_band` adds the pixels by their creases, each against the face it sees.

Matplotlib is imported only when figures are drawn.
"""

from __future__ import annotations

from ._creases import CreaseBand, crease_band, score_creases
from ._env import machine_description
from ._methods import MethodSpec, parse_method_spec, resolve_methods
from ._planes import (
    PlaneInfo,
    PlaneReference,
    plane_reference,
    score_planes,
    sensor_threshold,
)
from ._planes_run import (
    PlaneEvaluationResult,
    plane_summary,
    plane_table_markdown,
    run_plane_evaluation,
)
from ._protocol import (
    HIST_BIN_DEG,
    INVALID_POLICIES,
    FrameScore,
    Protocol,
    discontinuity_mask,
    score_frame,
    scoring_mask,
)
from ._run import EvaluationPlan, EvaluationResult, plan_evaluation, run_evaluation
from ._share import SceneShare, discontinuity_share, synth_discontinuity_shares
from ._store import FIELDS, read_results_csv
from ._summary import (
    ALL_GROUPS,
    group_levels_key,
    pooled_median,
    summarize,
    summary_markdown,
    threshold_curve,
)

__all__ = [
    "ALL_GROUPS",
    "FIELDS",
    "HIST_BIN_DEG",
    "INVALID_POLICIES",
    "CreaseBand",
    "EvaluationPlan",
    "EvaluationResult",
    "FrameScore",
    "MethodSpec",
    "PlaneEvaluationResult",
    "PlaneInfo",
    "PlaneReference",
    "Protocol",
    "SceneShare",
    "crease_band",
    "discontinuity_mask",
    "discontinuity_share",
    "group_levels_key",
    "machine_description",
    "parse_method_spec",
    "plan_evaluation",
    "plane_reference",
    "plane_summary",
    "plane_table_markdown",
    "pooled_median",
    "read_results_csv",
    "resolve_methods",
    "run_evaluation",
    "run_plane_evaluation",
    "score_creases",
    "score_frame",
    "score_planes",
    "scoring_mask",
    "sensor_threshold",
    "summarize",
    "summary_markdown",
    "synth_discontinuity_shares",
    "threshold_curve",
]
