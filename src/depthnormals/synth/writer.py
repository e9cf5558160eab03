"""Generating a synthetic benchmark on disk, resumably, and exporting it to the 3F2N format.

On-disk format (``format = "depthnormals-synth"``, version 1, ``storage="npy"``; see
docs/synthetic.md)::

    OUT/dataset.json                      every setting, the library version, the scene list
    OUT/<kind>/<scene>/scene.json         intrinsics, image size, camera poses, recipe, seed
    OUT/<kind>/<scene>/normals/0000.npy   float32 (H, W, 3) ground truth, NaN = no surface
    OUT/<kind>/<scene>/valid/0000.npy     bool (H, W): ground truth valid (a surface is seen)
    OUT/<kind>/<scene>/clean/0000.npy     float32 (H, W) planar depth, metres, 0 = invalid
    OUT/<kind>/<scene>/<model>/0000.npy   float32 (H, W) noisy depth of each noise model

Version 2 (``storage="compact"``, :mod:`depthnormals._compact`) keeps one file per view,
``OUT/<kind>/<scene>/views/0000.npz`` (octahedral normals, packed mask, depth lossless),
about 7x smaller. ``<kind>`` is ``indoor``, ``outdoor`` or ``mesh``. Every file is written
atomically, so a file that exists is complete; an interrupted run resumes by skipping the
views whose files all exist. A run into a folder made with other settings is refused (nothing is overwritten).
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._fingerprint import code_fingerprint
from .._progress import Progress
from ..camera import as_intrinsics
from ..cluster import check_batch_size
from ..datasets.synthetic import read_synthetic
from ..io import write_bytes_atomic, write_png
from ..render import KINECT_V2, KINECT_V2_SIZE
from . import noise as _noise
from .catalog import SCENE_SETS, make_scene, recipe_of_folder, scene_names
from .poses import PoseConstraints
from .scenes import load_mesh_scene
from .views import _KIND_ID, STORAGES, _prepare_scene_dir, _scene_poses, _write_json, _write_view

__all__ = ["FORMAT", "FORMAT_VERSION", "SynthSummary", "export_3f2n", "generate", "scene_plan"]

FORMAT = "depthnormals-synth"
#: The newest format version this code writes (``storage="compact"``; ``"npy"`` writes 1).
FORMAT_VERSION = 2


@dataclass(frozen=True)
class SynthSummary:
    """What :func:`generate` did (timings are not written to disk: files stay deterministic)."""

    root: Path
    frames: int
    written: int
    skipped: int
    seconds: float
    render_seconds: float

    @property
    def render_ms_per_frame(self) -> float:
        """Mean time of the clean 1x render per written frame, milliseconds."""
        return 1e3 * self.render_seconds / max(self.written, 1)


def _count(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")
    return int(value)


def scene_plan(indoor: int, outdoor: int, meshes: Sequence[str] = (), *,
               scenes: str = "procedural") -> list[tuple[str, int, str]]:
    """The scenes :func:`generate` renders, in order: ``(kind, index, folder name)``.

    Scene ``i`` of a kind is recipe ``i mod n`` of the ``n`` recipes of that kind in the scene
    set ``scenes`` (:func:`depthnormals.synth.catalog.scene_names`), in folder
    ``<recipe>-<i:02d>``; ``meshes`` are the mesh scene names (kind ``mesh``).

    Examples
    --------
    >>> scene_plan(2, 1)
    [('indoor', 0, 'living_room-00'), ('indoor', 1, 'office-01'), ('outdoor', 0, 'street-00')]
    """
    plan: list[tuple[str, int, str]] = []
    for kind, count in (("indoor", indoor), ("outdoor", outdoor)):
        names = scene_names(kind, scenes=scenes)
        plan += [(kind, i, f"{names[i % len(names)]}-{i:02d}") for i in range(count)]
    return plan + [("mesh", i, f"{name}-{i:02d}") for i, name in enumerate(meshes)]


def generate(out: str | Path, *, indoor: int = 10, outdoor: int = 10, views: int = 25, seed: int = 0,
             noise: Sequence[str] = ("kinect_v2",), meshes: Sequence[str | Path] = (),
             K: Any = KINECT_V2, size: tuple[int, int] = KINECT_V2_SIZE, near: float = 0.05,
             constraints: PoseConstraints | None = None, progress: bool = True,
             scheduler: str | None = None, batch_size: int = 16, storage: str = "npy",
             scenes: str = "procedural") -> SynthSummary:
    """Render a synthetic benchmark into ``out`` (clean frames plus one variant per noise model).

    Scene ``i`` of a kind uses recipe ``i mod 10`` of that kind (:func:`scene_names`) with its
    own seed; every random choice (scene, poses, noise of each view and model) draws from a
    generator seeded by ``(seed, kind, scene, purpose, view)``, so the output is byte-identical
    for the same arguments, and the same scene is the same whatever the other counts.

    Parameters
    ----------
    out : str or Path
        Output folder (created; may exist from an interrupted run with the same settings).
    indoor, outdoor : int, keyword-only
        Numbers of procedural indoor and outdoor scenes (>= 0).
    views : int, keyword-only
        Views per scene (>= 1).
    seed : int, keyword-only
        Master seed (>= 0).
    noise : sequence of str, keyword-only
        Noise model specs (:func:`depthnormals.synth.noise.parse_noise_spec`), e.g.
        ``("kinect_v2", "gaussian:sigma_px=0.1")``; one variant folder per model name.
    meshes : sequence of paths, keyword-only
        User mesh files (OBJ, PLY, STL, GLB; via trimesh), one scene each, kind ``mesh``.
    K : intrinsics, keyword-only
        Camera; default Kinect v2.
    size : (H, W), keyword-only
        Image size; default 424 x 512.
    near : float, keyword-only
        Near clipping distance, metres.
    constraints : PoseConstraints, optional, keyword-only
        Camera acceptance rules (default ``PoseConstraints()``).
    progress : bool, keyword-only
        Report progress on stderr (a tqdm bar on a terminal, else one line per view).
    scheduler : str, optional, keyword-only
        ``"local"``, ``"local:N"`` or ``"tcp://host:port"``: render on Dask
        (:func:`depthnormals.cluster.connect`; camera poses one task per scene, then views in
        tasks of ``batch_size``); the files are byte-identical to a serial run's.
    batch_size : int, keyword-only
        Views per Dask task.
    storage : {"npy", "compact"}, keyword-only
        ``"npy"``: format version 1, float32 ``.npy`` files (5.4 MB per 512 x 424 view with
        two noise models); ``"compact"``: version 2, one ``.npz`` per view (0.8 MB; normals
        octahedral, < 0.003 deg; every depth map bit-identical). The readers take both.
    scenes : {"procedural", "assets", "all"}, keyword-only
        Scene set (:func:`scene_names`): the procedural recipes (default; the files are the
        same bytes as before the option existed), the asset-mesh recipes of
        :mod:`depthnormals.synth.asset_scenes` (needs ``pip install 'depthnormals[assets]'``),
        or both; scene ``i`` of a kind uses recipe ``i mod n`` of the set's ``n`` recipes.

    Returns
    -------
    SynthSummary

    Raises
    ------
    ValueError
        Bad settings, an empty or corrupt mesh, a scene where no camera pose can be found,
        or an ``out`` folder that holds a dataset made with other settings.
    FileNotFoundError
        A mesh file is missing.
    OSError
        ``out`` cannot be created or written.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     s = generate(tmp, indoor=1, outdoor=0, views=1, size=(48, 64),
    ...                  K=(36.5, 36.5, 31.5, 23.5), progress=False)
    ...     sorted(p.name for p in (s.root / "indoor" / "living_room-00").iterdir())
    ['clean', 'kinect_v2', 'normals', 'scene.json', 'valid']
    """
    t_start = time.perf_counter()
    constraints = PoseConstraints() if constraints is None else constraints
    indoor = _count("indoor", indoor, 0)
    outdoor = _count("outdoor", outdoor, 0)
    views = _count("views", views, 1)
    seed = _count("seed", seed, 0)
    cam = as_intrinsics(K)
    if (not isinstance(size, (tuple, list)) or len(size) != 2
            or not all(isinstance(s, (int, np.integer)) and s >= 4 for s in size)):
        raise ValueError(f"size must be (H, W), integers >= 4; got {size!r}")
    h, w = int(size[0]), int(size[1])
    if storage not in STORAGES:
        raise ValueError(f"storage must be one of {', '.join(STORAGES)}; got {storage!r}")
    check_batch_size(batch_size)
    if isinstance(noise, str):
        noise = [noise]
    models: dict[str, dict] = {}
    for spec in noise:
        name, settings = _noise.parse_noise_spec(spec)
        if name in models:
            raise ValueError(f"noise model {name!r} is given twice; give each model once")
        models[name] = settings
    # load user meshes before anything is written: a bad file fails early
    mesh_scenes = [load_mesh_scene(p) for p in meshes]
    scene_set = _scene_set(scenes)
    if indoor + outdoor + len(mesh_scenes) == 0:
        raise ValueError("nothing to generate: pass indoor > 0, outdoor > 0 or a mesh")

    plan = scene_plan(indoor, outdoor, [s.name for s in mesh_scenes], scenes=scene_set)

    from .. import __version__

    settings = {
        "indoor": indoor, "outdoor": outdoor, "views": views, "seed": seed,
        "noise": [{"model": k, "settings": v} for k, v in models.items()],
        "meshes": [Path(p).name for p in meshes],
        "K": {"fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy},
        "size": [h, w], "near": float(near), "constraints": constraints.as_dict(),
    }
    if scene_set != "procedural":  # absent for the default: its dataset.json keeps its bytes
        settings["scenes"] = scene_set
    meta = {"format": FORMAT, "format_version": STORAGES[storage], "library_version": __version__,
            "library_code": code_fingerprint(), "settings": settings,
            "scenes": [f"{k}/{n}" for k, _, n in plan], "variants": ["clean", *models]}
    root = Path(out)
    if root.exists() and not root.is_dir():
        raise ValueError(f"output {root} exists and is not a folder")
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OSError(f"cannot create output folder {root}: {exc.strerror or exc}") from exc
    sidecar = root / "dataset.json"
    if sidecar.is_file():
        try:
            old = json.loads(sidecar.read_text())
        except json.JSONDecodeError as exc:
            raise ValueError(f"{sidecar} is not valid JSON; use an empty output folder") from exc
        if (old.get("format") != FORMAT or old.get("settings") != settings
                or old.get("format_version", 1) != STORAGES[storage]):
            raise ValueError(f"{root} holds a dataset made with other settings; pass the same "
                             "settings to resume it, or use another output folder")
        made_by = old.get("library_code")  # (absent: made before session 28, not known)
        if made_by is not None and made_by != meta["library_code"]:
            raise ValueError(f"{root} holds a dataset generated by another build of depthnormals "
                             f"(library_code {made_by}, this one {meta['library_code']}): views "
                             "generated now could differ from those already there; use another "
                             "output folder, or remove this one to generate it again")
    elif any(root.iterdir()):
        raise ValueError(f"output folder {root} is not empty and holds no {FORMAT} dataset; "
                         "use an empty or new folder")
    try:
        _write_json(sidecar, meta)
    except OSError as exc:
        raise OSError(f"cannot write to output folder {root}: {exc.strerror or exc}") from exc

    if scheduler is not None:
        from ._cluster import generate_on_cluster

        written, skipped, t_render = generate_on_cluster(
            scheduler, root, plan, [str(Path(p).absolute()) for p in meshes], views, seed, models, cam,
            (h, w), near, constraints, progress=progress, batch_size=batch_size, storage=storage)
        return SynthSummary(root, len(plan) * views, written, skipped, time.perf_counter() - t_start,
                            t_render)
    bar = Progress("synth", total=len(plan) * views, unit="view", enabled=progress)
    written = skipped = 0
    t_render = 0.0
    try:
        for kind, i, folder in plan:
            kid = _KIND_ID[kind]
            sdir = root / kind / folder
            if kind == "mesh":
                scene = mesh_scenes[i]
                scene_seed = None
            else:
                scene_seed = int(np.random.SeedSequence([seed, kid, i, 0]).generate_state(1)[0])
                scene = make_scene(recipe_of_folder(folder), seed=scene_seed)
            poses = _scene_poses(sdir, scene, kind, scene_seed, seed, kid, i, views, cam, (h, w),
                                 near, constraints)
            _prepare_scene_dir(sdir, models, storage)
            for view in range(views):
                seconds = _write_view(sdir, scene, poses[view], view, models, seed, kid, i, cam,
                                      (h, w), near, storage)
                if seconds is None:
                    skipped += 1
                else:
                    t_render += seconds
                    written += 1
                bar.update()
    finally:
        bar.close()
    return SynthSummary(root, len(plan) * views, written, skipped, time.perf_counter() - t_start,
                        t_render)


def _scene_set(scenes: str) -> str:
    if scenes not in SCENE_SETS:
        raise ValueError(f"scenes must be one of {', '.join(SCENE_SETS)}; got {scenes!r}")
    if scenes != "procedural":
        from .assets import asset_root

        asset_root()  # fail before anything is written when the asset package is missing
    return scenes


def export_3f2n(root: str | Path, out: str | Path, *, variant: str = "clean") -> list[Path]:
    """Export a generated dataset to the 3F2N dataset format, for the reference code.

    Per scene ``out/<kind>/<scene>/``: ``depth/%06d.bin`` (little-endian float32, row-major;
    pixels without depth are 1.0, the 3F2N background value), ``normal/%06d.png`` (16-bit
    RGB, ``value = round((n + 1) / 2 * 65535)``, camera-facing normals, background
    (65535, 65535, 65535)) and ``params.txt`` (``fx fy cx cy N`` with cx, cy on MATLAB's
    1-based grid, i.e. ours + 1). Frames are numbered from 000001.

    Parameters
    ----------
    root : str or Path
        A dataset written by :func:`generate`.
    out : str or Path
        Output folder (created).
    variant : str, keyword-only
        ``"clean"`` or a noise model name present in the dataset.

    Returns
    -------
    list of Path
        The scene folders written.
    """
    root = Path(root)
    sidecar = root / "dataset.json"
    if not sidecar.is_file():
        raise FileNotFoundError(f"{root} holds no {FORMAT} dataset (dataset.json missing)")
    meta = json.loads(sidecar.read_text())
    if variant not in meta["variants"]:
        raise ValueError(f"variant {variant!r} not in the dataset; valid: {', '.join(meta['variants'])}")
    out = Path(out)
    written = []
    for rel in meta["scenes"]:
        sdir = root / rel
        info = json.loads((sdir / "scene.json").read_text())
        dst = out / rel
        (dst / "depth").mkdir(parents=True, exist_ok=True)
        (dst / "normal").mkdir(parents=True, exist_ok=True)
        k = 0
        for k, frame in enumerate(read_synthetic(sdir, variants=[variant]), start=1):  # either layout
            z, n = frame.depth.astype("<f4"), frame.normals
            z = np.where(np.isfinite(z) & (z > 0), z, np.float32(1.0)).astype("<f4")
            write_bytes_atomic(dst / "depth" / f"{k:06d}.bin", z.tobytes())
            ok = np.all(np.isfinite(n), axis=-1)
            enc = np.clip(np.rint((np.nan_to_num(n) + 1.0) * 0.5 * 65535.0), 0, 65535).astype(np.uint16)
            enc[~ok] = 65535
            write_png(dst / "normal" / f"{k:06d}.png", enc)
        Kd = info["K"]
        text = f"{Kd['fx']!r} {Kd['fy']!r} {Kd['cx'] + 1.0!r} {Kd['cy'] + 1.0!r} {k}\n"
        write_bytes_atomic(dst / "params.txt", text.encode())
        written.append(dst)
    return written
