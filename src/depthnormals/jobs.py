"""Normals of many depth frames into a folder: plan (input, output) pairs, skip done, run.

What ``depthnormals estimate IN... -o DIR`` runs. :func:`plan_estimate` expands the inputs
(depth files, glob patterns, folders of depth files, dataset folders that
:func:`depthnormals.datasets.open` reads) into :class:`EstimateJob` s, one per frame, each
with its output path; :func:`run_estimate` drops the jobs whose output already exists
(outputs are written atomically, so a file that exists is complete and a killed run resumes
where it stopped), and runs the rest with :func:`depthnormals.cluster.map_batches`: on the
library's threads, one frame per thread, or on a Dask cluster.

Output names: a depth file keeps its path relative to the folder it was found in (the
folder given, the fixed part of a glob pattern, or its own folder), with the suffix of the
output format; a dataset frame is written as ``<group>/<name>``. Two inputs mapping to the
same output are refused. Files that a folder or a glob brings in but that are no depth
images (colour PNGs, (H, W, 3) arrays: :func:`depthnormals.io.not_depth_reason`) are skipped
and counted (:attr:`RunSummary.not_depth`); a file named on its own is always read.

The manifest: every output folder holds :data:`MANIFEST` (``depthnormals-manifest.json``),
what its normals were made with (:func:`manifest_settings`: method, options, depth scale,
invalid codes, maximum depth, intrinsics, format, colouring, the digest of the library's
code) and the library version. A rerun with other settings or another build of the library
is refused before any work (:class:`SettingsMismatch`, which says what differs and how to
recompute: ``resume=False`` / ``--no-resume``); outputs found in a folder without a manifest
are recomputed, never taken as done, and so is an output older than its depth file. A run
that fails before it writes any frame leaves no manifest, and no output folder it created
itself.

The inputs log: beside the manifest, :data:`INPUTS_LOG` (``depthnormals-inputs.log``) records,
for each output as it is written, what it was computed from: a depth file's size and
modification time, a dataset frame's digest (its depth and camera, bit for bit). A resumed run
skips an output only when its input is recorded and unchanged, so a regenerated dataset read
into the same folder, or a depth file replaced by another (an older copy included), is
computed again; an output whose line a killed run did not write is computed again too.
"""

from __future__ import annotations

import glob
import json
import shutil
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from ._fingerprint import array_digest, code_fingerprint
from .camera import Intrinsics, as_intrinsics, lens_distortion, undistort_depth
from .io import DEPTH_SUFFIXES, VIS_CONVENTIONS, not_depth_reason

__all__ = ["FORMATS", "INPUTS_LOG", "MANIFEST", "EstimateJob", "EstimateSettings", "RunSummary",
           "SettingsMismatch", "estimate_job", "manifest_settings", "normals_and_uncertainty",
           "plan_estimate", "run_estimate", "uncertainty_path", "write_uncertainty"]

#: The manifest file of an output folder (see the module docstring).
MANIFEST = "depthnormals-manifest.json"
#: The log of what each output of a folder was computed from (see the module docstring).
INPUTS_LOG = "depthnormals-inputs.log"
_MANIFEST_FORMAT = "depthnormals-estimate"

#: Output formats of the many-frames form (the suffix of each output file).
FORMATS = ("npy", "png", "vis.png", "ply")
_MAGIC = set("*?[")


@dataclass(frozen=True)
class EstimateSettings:
    """What every frame of a run shares: the method, its options, how depth files are read
    (scale, invalid raw codes, maximum depth in metres, the lens distortion undone first), the
    ``.vis.png`` colouring and whether the expected-error map is written beside each output
    (:func:`uncertainty_path`)."""

    method: str
    options: Mapping[str, Any] = field(default_factory=dict)
    depth_scale: float | None = None
    invalid: tuple[float, ...] = ()
    max_depth: float | None = None
    vis: str = "3f2n"
    uncertainty: bool = False
    distortion: tuple[float, ...] = ()


class SettingsMismatch(ValueError):
    """An output folder holds normals made with other settings (see the module docstring)."""


@dataclass(frozen=True)
class EstimateJob:
    """One frame to do.

    Attributes
    ----------
    output : Path
        Where its normals go (suffix = format).
    K : Intrinsics
        Its camera.
    source : Path or None
        A depth file read by the worker (``depthnormals.io.read_depth``), or None when the
        depth is carried in ``depth`` (a frame of a dataset reader).
    depth : ndarray (H, W) or None
        The depth of a dataset frame, metres.
    label : str
        Name shown by the progress bar.
    undistorted : bool
        A dataset frame whose reader has undone its lens already (``meta["undistorted"]``).
    """

    output: Path
    K: Intrinsics
    source: Path | None = None
    depth: np.ndarray | None = field(default=None, repr=False, compare=False)
    label: str = ""
    undistorted: bool = False


@dataclass(frozen=True)
class RunSummary:
    """What :func:`run_estimate` did: frames planned, computed now, found done, seconds;
    ``not_depth``: the (file, reason) pairs skipped as no depth image; ``no_normal``: the
    outputs written now that hold no finite normal (all NaN); ``stale``: outputs of other or
    unknown settings that a forced run found in the folder and did not replace (the folder
    then gets no manifest, so a later run recomputes them)."""

    planned: int
    written: int
    skipped: int
    seconds: float
    not_depth: tuple[tuple[str, str], ...] = ()
    no_normal: tuple[str, ...] = ()
    stale: tuple[str, ...] = ()


def _is_glob(text: str) -> bool:
    return any(c in _MAGIC for c in text)


def _glob_root(pattern: str) -> Path:
    parts = Path(pattern).parts
    fixed = []
    for part in parts[:-1]:
        if _is_glob(part):
            break
        fixed.append(part)
    return Path(*fixed) if fixed else Path(".")


def _depth_files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix.lower() in DEPTH_SUFFIXES)


def _dataset_frames(folder: Path) -> Iterator[Any] | None:
    """The frames of a dataset folder, or None when it holds no known dataset layout."""
    from . import datasets

    frames = iter(datasets.open(folder))
    try:
        first = next(frames)
    except StopIteration:
        return iter(())
    except ValueError as exc:
        if "no known dataset layout" in str(exc):
            return None
        raise

    def chain() -> Iterator[Any]:
        yield first
        yield from frames

    return chain()


def is_dataset_file(path: Path) -> bool:
    """A file without a depth image's suffix that a dataset reader takes (a ROS bag, NYU's
    labeled ``.mat``): an input of many frames."""
    from . import datasets

    if not path.is_file() or path.suffix.lower() in DEPTH_SUFFIXES:
        return False
    try:
        datasets.detect_format(path)
    except ValueError:
        return False
    return True


def _stem(rel: Path) -> str:
    return rel.with_suffix("").as_posix()


def plan_estimate(inputs: Sequence[str | Path], out_dir: str | Path, *, K: Any = None,
                  fmt: str = "npy",
                  on_skip: Callable[[Path, str], None] | None = None) -> Iterator[EstimateJob]:
    """The frames of ``inputs`` with their output paths under ``out_dir`` (lazily).

    Parameters
    ----------
    inputs : sequence of str or Path
        Depth files (``.npy``, ``.png``, ``.tif``, ``.bin``), glob patterns (``"seq/*.png"``,
        ``"**"`` recursive), folders of depth files (searched recursively), or dataset
        folders (:func:`depthnormals.datasets.open`; they bring their own intrinsics).
    out_dir : str or Path
        Output folder.
    K : intrinsics, optional
        Camera of the depth files (required when there are any).
    fmt : {"npy", "png", "vis.png", "ply"}
        Output format.
    on_skip : callable, optional
        ``on_skip(path, reason)`` for each file of a folder or glob that is no depth image
        (it is left out).

    Yields
    ------
    EstimateJob

    Raises
    ------
    FileNotFoundError
        An input that does not exist, or a glob that matches no depth file.
    ValueError
        A bad format, a depth file without ``K``, an empty folder, or two inputs with the same
        output path.
    """
    if fmt not in FORMATS:
        raise ValueError(f"output format {fmt!r} not known; use one of {', '.join(FORMATS)}")
    if isinstance(inputs, (str, Path)):
        inputs = [inputs]
    if not inputs:
        raise ValueError("no inputs given")
    out = Path(out_dir).absolute()  # workers of a cluster may run elsewhere
    cam = None if K is None else as_intrinsics(K)
    seen: dict[Path, str] = {}

    def job(output: Path, origin: str, **kw: Any) -> EstimateJob:
        if output in seen:
            raise ValueError(f"{origin} and {seen[output]} would both be written to {output}; "
                             "give them separate runs or output folders")
        seen[output] = origin
        return EstimateJob(output=output, **kw)

    def depth_only(paths: Iterable[Path]) -> list[Path]:
        kept = []
        for p in paths:
            reason = not_depth_reason(p)
            if reason is None:
                kept.append(p)
            elif on_skip is not None:
                on_skip(p, reason)
        return kept

    def files(paths: Iterable[Path], root: Path) -> Iterator[EstimateJob]:
        if cam is None:
            raise ValueError("depth files need the camera: pass --intrinsics/-K (K=...)")
        for p in paths:
            rel = p.relative_to(root) if p.is_relative_to(root) else Path(p.name)
            yield job(out / f"{_stem(rel)}.{fmt}", str(p), K=cam, source=p.absolute(), label=str(rel))

    def dataset(frames: Iterable[Any], path: Path) -> Iterator[EstimateJob]:
        for f in frames:
            rel = f"{f.group}/{f.name}" if f.group else f.name
            yield job(out / f"{rel}.{fmt}", f"{path}:{rel}", K=as_intrinsics(f.K), depth=f.depth,
                      label=rel, undistorted=bool(f.meta.get("undistorted")))

    for item in inputs:
        text = str(item)
        path = Path(text)
        if _is_glob(text) and not path.exists():
            found = sorted(Path(p) for p in glob.glob(text, recursive=True)
                           if Path(p).is_file() and Path(p).suffix.lower() in DEPTH_SUFFIXES)
            if not found:
                raise FileNotFoundError(f"{text} matches no depth file ({', '.join(DEPTH_SUFFIXES)})")
            kept = depth_only(found)
            if not kept:
                raise ValueError(f"{text} matches {len(found)} file(s), none of them a depth image "
                                 "(colour images or other arrays)")
            yield from files(kept, _glob_root(text))
        elif path.is_file():
            if is_dataset_file(path):
                from . import datasets

                yield from dataset(datasets.open(path), path)
            else:
                yield from files([path], path.parent)
        elif path.is_dir():
            frames = _dataset_frames(path)
            if frames is None:
                found = _depth_files(path)
                if not found:
                    raise ValueError(f"{path} holds no dataset this library reads and no depth file "
                                     f"({', '.join(DEPTH_SUFFIXES)})")
                kept = depth_only(found)
                if not kept:
                    raise ValueError(f"{path} holds {len(found)} file(s) with a depth suffix, none of "
                                     "them a depth image (colour images or other arrays)")
                yield from files(kept, path)
                continue
            yield from dataset(frames, path)
        else:
            raise FileNotFoundError(f"input {text} does not exist")


def uncertainty_path(output: str | Path) -> Path:
    """Where the expected-error map of the normals at ``output`` goes:
    ``<name>.uncertainty.npy`` beside them (``n.vis.png`` -> ``n.uncertainty.npy``)."""
    p = Path(output)
    name = p.name
    for suffix in (".vis.png", ".png", ".npy", ".ply"):
        if name.lower().endswith(suffix):
            name = name[:-len(suffix)]
            break
    return p.with_name(name + ".uncertainty.npy")


def write_uncertainty(path: str | Path, uncertainty: np.ndarray) -> None:
    """Write an expected-error map (float32 (H, W), degrees) as ``.npy``, atomically."""
    import io as _io

    from .io import write_bytes_atomic

    buf = _io.BytesIO()
    np.save(buf, np.asarray(uncertainty, dtype=np.float32))
    write_bytes_atomic(path, buf.getvalue())


def normals_and_uncertainty(depth: np.ndarray, K: Any, method: str, options: Mapping[str, Any],
                            uncertainty: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """The normals of ``method`` and, with ``uncertainty``, their expected-error map (else
    None): the registry's ``compute_normals`` / ``return_uncertainty=True``."""
    from .ddm.uncertainty import normals_with_uncertainty
    from .registry import compute_normals

    if not uncertainty:
        return compute_normals(depth, K, method=method, **dict(options)), None
    return normals_with_uncertainty(compute_normals, depth, K, method=method, depth_scale=None,
                                    options=dict(options))


def _write(path: Path, normals: np.ndarray, depth: np.ndarray, K: Intrinsics, vis: str = "3f2n",
           uncertainty: np.ndarray | None = None) -> None:
    """The normals at ``path``: a point cloud for ``.ply`` (with the expected-error map as its
    ``uncertainty`` channel when given), else a normal map (which does not carry it)."""
    from . import io

    if path.name.lower().endswith(".ply"):
        io.write_ply(path, depth, K, normals, uncertainty=uncertainty)
    else:
        io.write_normals(path, normals, vis=vis)


def estimate_job(job: EstimateJob, settings: EstimateSettings) -> tuple[str, int]:
    """Read, estimate and write one frame (atomically); returns the output path and its
    number of finite normals (0: all NaN).

    The unit of work of :func:`run_estimate`, run on a worker thread or a Dask worker. An
    error names the input file.
    """
    from .io import read_depth

    if job.source is not None:
        depth = read_depth(job.source, depth_scale=settings.depth_scale, invalid=settings.invalid,
                           max_depth=settings.max_depth)
    else:
        depth = job.depth
        if settings.max_depth is not None:
            depth = np.where(depth > settings.max_depth, np.nan, depth).astype(depth.dtype)
    if settings.distortion:  # onto the pinhole grid of K (the PLY's points too)
        depth = undistort_depth(depth, job.K, settings.distortion)
    try:
        normals, unc = normals_and_uncertainty(depth, job.K, settings.method, settings.options,
                                               settings.uncertainty)
    except (ValueError, TypeError) as exc:
        where = str(job.source) if job.source is not None else job.label
        if where in str(exc):
            raise
        raise type(exc)(f"{where}: {exc}") from exc
    job.output.parent.mkdir(parents=True, exist_ok=True)
    if unc is not None:  # first: a finished output implies its map (resume checks the output)
        write_uncertainty(uncertainty_path(job.output), unc)
    _write(job.output, normals, depth, job.K, settings.vis, unc)
    return str(job.output), int(np.count_nonzero(np.isfinite(normals[..., 0])))


def manifest_settings(settings: EstimateSettings, K: Any, fmt: str) -> dict[str, Any]:
    """The settings a manifest records and a resumed run must match: method, options, depth
    scale, invalid codes, maximum depth, intrinsics (None: each dataset frame's own),
    output format and, for ``vis.png``, the colouring; ``"uncertainty": True`` when the
    expected-error maps are written and ``"distortion"`` when the depth is undistorted first
    (each absent otherwise, so that the manifests of runs without them still match); and
    ``library_code``, the digest of the library's modules
    (:func:`depthnormals._fingerprint.code_fingerprint`): outputs of an edited or upgraded
    library are not taken as done (its version string does not change between development
    builds)."""
    cam = None if K is None else as_intrinsics(K)
    extra: dict[str, Any] = {"uncertainty": True} if settings.uncertainty else {}
    if settings.distortion:
        extra["distortion"] = [float(c) for c in settings.distortion]
    return {
        "method": settings.method,
        "options": json.loads(json.dumps(dict(settings.options), sort_keys=True, default=repr)),
        "depth_scale": settings.depth_scale,
        "invalid": [float(c) for c in settings.invalid],
        "max_depth": settings.max_depth,
        "intrinsics": None if cam is None else {"fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy},
        "format": fmt,
        "vis": settings.vis if fmt == "vis.png" else None,
        **extra,
        "library_code": code_fingerprint(),
    }


def _changed_since(job: EstimateJob) -> bool:
    """Whether the job's depth file was written after its output (make's rule: the output is
    stale and is computed again); False for a frame a dataset reader carries."""
    if job.source is None:
        return False
    try:
        return Path(job.source).stat().st_mtime_ns > job.output.stat().st_mtime_ns
    except OSError:
        return True


def _input_key(job: EstimateJob) -> str:
    """What the job's output is computed from, as the inputs log records it: a depth file's
    size and modification time (ns), or the digest of a dataset frame's depth and camera."""
    if job.source is not None:
        try:
            st = Path(job.source).stat()
        except OSError:
            return "file missing"
        return f"file {st.st_size} {st.st_mtime_ns}"
    return f"data {array_digest(job.depth, job.K.matrix)}"


def _read_inputs_log(out: Path) -> dict[str, str]:
    """The inputs log of ``out``: output (relative, posix) -> input key, the last line of each
    output winning; a line cut short by a killed run is ignored."""
    path = out / INPUTS_LOG
    return _parse_inputs_log(path.read_text(errors="replace").splitlines()) if path.is_file() else {}


def _parse_inputs_log(lines: list[str]) -> dict[str, str]:
    found: dict[str, str] = {}
    for line in lines:
        try:
            entry = json.loads(line)
            found[str(entry["output"])] = str(entry["input"])
        except (json.JSONDecodeError, KeyError, TypeError):
            continue
    return found


def _log_line(rel: str, key: str) -> str:
    return json.dumps({"output": rel, "input": key}) + "\n"


def _open_inputs_log(out: Path) -> Any:
    """The inputs log opened for appending, on a line of its own (after a line a killed run
    cut short, a newline first)."""
    path = out / INPUTS_LOG
    torn = False
    if path.is_file() and path.stat().st_size:
        with open(path, "rb") as f:
            f.seek(-1, 2)
            torn = f.read(1) != b"\n"
    log = open(path, "a", encoding="utf-8")  # the caller closes it
    if torn:
        log.write("\n")
    return log


def _compact_inputs_log(out: Path) -> None:
    """Rewrite the log (atomically) with one line per output that exists, when it has more."""
    from .io import write_bytes_atomic

    path = out / INPUTS_LOG
    if not path.is_file():
        return
    lines = path.read_text(errors="replace").splitlines()
    found = {rel: key for rel, key in _parse_inputs_log(lines).items() if (out / rel).is_file()}
    if len(found) != len(lines):
        write_bytes_atomic(path, "".join(_log_line(r, k) for r, k in sorted(found.items())).encode())


def _read_manifest(path: Path) -> dict[str, Any] | None:
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError, OSError) as exc:
        raise SettingsMismatch(f"{path} is not a readable manifest ({exc}); delete it and pass "
                               "--no-resume (resume=False) to recompute the folder") from exc
    if not isinstance(data, dict) or data.get("format") != _MANIFEST_FORMAT:
        raise SettingsMismatch(f"{path} is not a depthnormals estimate manifest; use another output "
                               "folder")
    return data


def _differences(old: Mapping[str, Any], new: Mapping[str, Any]) -> str:
    keys = [k for k in new if old.get(k) != new[k]] + [k for k in old if k not in new]
    return "; ".join(f"{k} {json.dumps(old.get(k))} before, {json.dumps(new.get(k))} now" for k in keys)


def _check_manifest(out: Path, wanted: dict[str, Any], resume: bool) -> bool:
    """Refuse a resumed run into a folder made with other settings; True when the folder's
    manifest matches (its outputs may be skipped)."""
    old = _read_manifest(out / MANIFEST)
    if old is None:
        return False
    if old.get("settings") == wanted:
        return True
    if resume:
        diff = _differences(old.get("settings") or {}, wanted)
        raise SettingsMismatch(
            f"{out} holds normals made with other settings ({diff}); "
            "to recompute every frame with the new settings pass --no-resume (resume=False), or write "
            "to another output folder")
    return False


def _write_manifest(out: Path, settings: dict[str, Any]) -> None:
    from . import __version__
    from .io import write_bytes_atomic

    data = {"format": _MANIFEST_FORMAT, "manifest_version": 1, "library_version": __version__,
            "settings": settings}
    write_bytes_atomic(out / MANIFEST, (json.dumps(data, indent=2) + "\n").encode())


def _remove_run_traces(out: Path, created: bool) -> None:
    """After a run that wrote no frame: its manifest, and the folder if this run created it
    (only when nothing but empty folders is left in it)."""
    (out / MANIFEST).unlink(missing_ok=True)
    (out / INPUTS_LOG).unlink(missing_ok=True)
    if created and out.is_dir() and not any(p.is_file() for p in out.rglob("*")):
        shutil.rmtree(out, ignore_errors=True)


def run_estimate(inputs: Sequence[str | Path], out_dir: str | Path, *, method: str, K: Any = None,
                 options: Mapping[str, Any] | None = None, depth_scale: float | None = None,
                 fmt: str = "npy", resume: bool = True, progress: bool = False,
                 scheduler: Any = None, batch_size: int = 16, invalid: Sequence[float] = (),
                 max_depth: float | None = None,
                 vis: str = "3f2n", uncertainty: bool = False,
                 distortion: Sequence[float] | None = None) -> RunSummary:
    """Estimate the normals of every frame of ``inputs`` into ``out_dir``.

    Parameters
    ----------
    inputs, out_dir, K, fmt
        See :func:`plan_estimate`.
    method : str
        A name from :func:`depthnormals.methods`.
    options : mapping, optional
        Options of the method.
    depth_scale : float, optional
        Metres per unit of integer depth files (e.g. 0.001 for millimetre PNGs).
    resume : bool, default True
        Skip frames whose output exists and whose folder's manifest holds the same settings
        (complete: every output is written atomically); a folder made with other settings
        raises :class:`SettingsMismatch`. False recomputes and replaces every output.
    progress : bool, default False
        Progress on stderr (:class:`depthnormals.cluster.Progress`).
    scheduler : str or distributed.Client, optional
        ``"local"``, ``"local:N"`` or ``"tcp://host:port"``: run on Dask
        (:func:`depthnormals.cluster.connect`); or an open ``distributed.Client`` to run
        on (left open); default on this machine's threads. Workers must see the input and
        output paths (a shared file system on several machines).
    batch_size : int, default 16
        Frames per Dask task.
    invalid : sequence of numbers, optional
        Raw values of depth files that mark invalid pixels (e.g. ``(65535,)``).
    max_depth : float, optional
        Depth beyond this many metres is invalid.
    vis : {"3f2n", "open3d"}
        Colouring of ``vis.png`` outputs (:func:`depthnormals.io.normals_to_rgb8`).
    uncertainty : bool, default False
        Also write each frame's expected angular error (degrees, float32 (H, W)) to
        ``<name>.uncertainty.npy`` beside its output (:func:`uncertainty_path`, atomically,
        before the normals); a ``.ply`` output also carries it per point (``float
        uncertainty``). Recorded in the manifest. Only for the methods of
        ``return_uncertainty=True``.
    distortion : sequence of 4, 5, 8 or 12 floats, optional
        The lens distortion of the depth images (OpenCV's order, ``k1, k2, p1, p2[, k3[, k4,
        k5, k6[, s1, s2, s3, s4]]]``): each frame is resampled onto the pinhole grid of its
        ``K`` before its normals (:func:`depthnormals.undistort_depth`); the outputs, a
        ``.ply``'s points included, are on that grid. Dataset frames too, but a frame whose
        reader has undone its lens already (a real-sensor folder's ``distortion``, a ROS bag's
        camera: ``meta["undistorted"]``) raises ValueError rather than be undone twice.
        Recorded in the manifest.

    Returns
    -------
    RunSummary

    Raises
    ------
    SettingsMismatch
        ``out_dir`` holds normals made with other settings and ``resume`` is True.
    """
    from ._progress import Progress
    from ._validate import check_choice, check_positive
    from .cluster import check_batch_size, connect, map_batches
    from .registry import get_estimator

    get_estimator(method[:-1] if method.endswith("+") else method)  # a bad name fails before any work
    if scheduler is not None and not isinstance(scheduler, str) and not hasattr(scheduler, "submit"):
        raise TypeError(f"scheduler must be an address ('local', 'local:N', 'tcp://host:port') or an "
                        f"open distributed.Client; got {type(scheduler).__name__}")
    check_choice(vis, "vis", VIS_CONVENTIONS)
    check_batch_size(batch_size)
    if fmt not in FORMATS:
        raise ValueError(f"output format {fmt!r} not known; use one of {', '.join(FORMATS)}")
    if uncertainty:
        from .ddm.uncertainty import UNCERTAINTY_METHODS

        if method not in UNCERTAINTY_METHODS:
            raise ValueError(f"--uncertainty (uncertainty=True) is supported for methods "
                             f"{', '.join(UNCERTAINTY_METHODS)}; got method {method!r}")
    settings = EstimateSettings(method, dict(options or {}), depth_scale, tuple(float(c) for c in invalid),
                                check_positive(max_depth, "max_depth", allow_none=True), vis,
                                bool(uncertainty), lens_distortion(distortion))
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"output {out} exists and is not a folder")
    wanted = manifest_settings(settings, K, fmt)
    trusted = _check_manifest(out, wanted, resume) if out.is_dir() else False
    created = not out.exists()
    # fresh: nothing in the folder yet, so the manifest goes in before the first frame and an
    # interrupted run resumes; otherwise (outputs of other or unknown settings) every frame is
    # recomputed and the manifest is written once all are, so no old output passes for new
    fresh = created or not any(p.is_file() for p in out.rglob("*"))
    if not trusted and not fresh:
        (out / MANIFEST).unlink(missing_ok=True)
        (out / INPUTS_LOG).unlink(missing_ok=True)  # every output there is computed again
    recorded = _read_inputs_log(out) if trusted else {}
    root = out.absolute()
    keys: dict[Path, str] = {}
    t0 = time.perf_counter()
    counts = {"planned": 0, "skipped": 0, "written": 0}
    planned: set[Path] = set()
    not_depth: list[tuple[str, str]] = []
    no_normal: list[str] = []

    def todo() -> Iterator[EstimateJob]:
        for job in plan_estimate(inputs, out, K=K, fmt=fmt,
                                 on_skip=lambda p, why: not_depth.append((str(p), why))):
            if settings.distortion and job.undistorted:
                raise ValueError(f"{job.label}: its reader has undone the frame's lens already; "
                                 "distortion (--distortion) would undo it twice: leave it out")
            counts["planned"] += 1
            if not trusted and not fresh:
                planned.add(job.output)
            key = _input_key(job)
            if (resume and trusted and job.output.is_file() and not _changed_since(job)
                    and recorded.get(job.output.relative_to(root).as_posix()) == key):
                counts["skipped"] += 1
                bar.update(f"{job.label} (done before)")
                continue
            keys[job.output] = key  # logged once the output is written (on_done)
            if fresh and counts["planned"] - counts["skipped"] == 1:  # the first frame to compute
                out.mkdir(parents=True, exist_ok=True)
                _write_manifest(out, wanted)
            yield job

    func = partial(estimate_job, settings=settings)
    log = None
    try:
        with Progress("estimate", unit="frame", enabled=progress) as bar:
            def on_done(job: EstimateJob, result: tuple[str, int]) -> None:
                nonlocal log
                if log is None:
                    log = _open_inputs_log(out)
                log.write(_log_line(job.output.relative_to(root).as_posix(), keys.pop(job.output)))
                log.flush()
                counts["written"] += 1
                if result[1] == 0:
                    no_normal.append(result[0])
                bar.update(job.label)

            if scheduler is not None and not isinstance(scheduler, str):  # an open client
                results = map_batches(func, todo(), client=scheduler, batch_size=batch_size,
                                      on_done=on_done)
            elif scheduler is not None:
                with connect(scheduler) as cl:
                    results = map_batches(func, todo(), client=cl, batch_size=batch_size, on_done=on_done)
            else:
                results = map_batches(func, todo(), on_done=on_done)
    except BaseException:
        if log is not None:
            log.close()
        if fresh and counts["written"] == 0:
            _remove_run_traces(out, created)
        raise
    if log is not None:
        log.close()
        _compact_inputs_log(out)
    if counts["planned"] == 0:
        raise ValueError(f"the inputs {', '.join(map(str, inputs))} hold no frame")
    stale: list[str] = []
    if not trusted and not fresh:
        stale = sorted(str(p) for p in out.absolute().rglob(f"*.{fmt}") if p.is_file() and p not in planned)
        if not stale:
            _write_manifest(out, wanted)
    return RunSummary(counts["planned"], len(results), counts["skipped"], time.perf_counter() - t0,
                      tuple(not_depth), tuple(sorted(no_normal)), tuple(stale))
