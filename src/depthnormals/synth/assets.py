"""Real asset meshes for the synthetic scenes, taken from a PyPI package, with their licences.

Every mesh comes from ``pybullet_data``, the data folder that ships inside the ``pybullet``
wheel (``pip install pybullet``, or ``pip install 'depthnormals[assets]'``); nothing is
downloaded at run time. :data:`ASSETS` records, for every asset a scene recipe may use, the
package, the path inside it, the licence, the scale to metres, the up axis and a category.

Licences (read from the wheel of pybullet 3.2.7): the package and its data folder are under
the zlib licence (``pybullet-3.2.7.dist-info/LICENSE.txt``: "The files in this repository
are licensed under the zlib license, except for the files under 'Extras' and
examples/ThirdPartyLibs"; the data folder is neither). Folders with a licence of their own
say so in the table: ``franka_panda/LICENSE.txt`` (Apache-2.0), ``kuka_iiwa/model.urdf``
(BSD-2-Clause header, Krug & Stoyanov, Orebro University). Folders whose own notice is
not a plain reuse licence are left out: ``bicycle`` (CC BY-SA 3.0, share-alike),
``laikago`` ("used by permission of Unitree"), and the duck and bunny models (third-party
sample and scan licences).

Robots are URDF files assembled at their rest pose (every joint at 0) by :func:`load_asset`:
a link's visuals are meshes (OBJ/STL through trimesh) or URDF boxes, cylinders and spheres
(tessellated like the procedural parts).

Examples
--------
>>> from depthnormals.synth.assets import ASSETS
>>> a = ASSETS["mug"]
>>> a.package, a.path, a.licence
('pybullet', 'pybullet_data/objects/mug.obj', 'zlib')
"""

from __future__ import annotations

import functools
import importlib.util
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .meshes import Mesh, box, cylinder, icosphere, merge

__all__ = ["ASSETS", "Asset", "asset_root", "assets_available", "load_asset"]


@dataclass(frozen=True)
class Asset:
    """One asset mesh (or URDF-assembled robot) and where it comes from.

    Attributes
    ----------
    package : str
        PyPI distribution that ships the file (``pip install`` name).
    path : str
        Path inside the installed distribution (``pybullet_data/...``).
    licence : str
        SPDX-like licence of the file, as its package or folder states it.
    scale : float
        Multiplier from file units to metres (applied before the recipe's own resizing).
    up : str
        The file's up axis (``"y"`` or ``"z"``); :func:`load_asset` turns it to world z.
    category : str
        ``"clutter"``, ``"toy"``, ``"furniture"``, ``"robot"``, ``"vehicle"``,
        ``"street"``, ``"building"`` or ``"ground"``.
    note : str
        Provenance notes (upstream origin, licence file).
    """

    package: str
    path: str
    licence: str
    scale: float
    up: str
    category: str
    note: str = ""


_Z = "zlib"
_PB = "pybullet"
_PBNOTE = "pybullet wheel licence (zlib) covers pybullet_data"

#: Random objects of ``pybullet_data/random_urdfs`` used as clutter (URDF scale 0.015; ~9 cm).
RANDOM_OBJECTS = ("000", "008", "034", "053", "080", "101", "123", "156", "213", "278", "302", "315",
                  "395", "433", "503", "552", "580", "706", "782", "882", "922", "933")

ASSETS: dict[str, Asset] = {
    "mug": Asset(_PB, "pybullet_data/objects/mug.obj", _Z, 1.0, "z", "clutter", _PBNOTE),
    "lego": Asset(_PB, "pybullet_data/lego/lego.obj", _Z, 0.1, "z", "toy", _PBNOTE),
    "domino": Asset(_PB, "pybullet_data/domino/domino.obj", _Z, 1.0, "z", "toy",
                    "domino/license.txt: model by Erwin Coumans; cite PyBullet"),
    "shape_sorter": Asset(_PB, "pybullet_data/toys/shape_sorter.obj", _Z, 0.5, "z", "toy", _PBNOTE),
    "toy_cylinder": Asset(_PB, "pybullet_data/toys/cylinder.obj", _Z, 1.0, "z", "toy", _PBNOTE),
    "toy_prism": Asset(_PB, "pybullet_data/toys/prism.obj", _Z, 1.0, "z", "toy", _PBNOTE),
    "concave_box": Asset(_PB, "pybullet_data/toys/concave_box.obj", _Z, 0.15, "z", "clutter", _PBNOTE),
    "tray": Asset(_PB, "pybullet_data/tray/tray_textured.obj", _Z, 0.4, "z", "clutter", _PBNOTE),
    "torus": Asset(_PB, "pybullet_data/torus/torus_textured.obj", _Z, 0.12, "y", "clutter", _PBNOTE),
    "soccerball": Asset(_PB, "pybullet_data/soccerball.obj", _Z, 0.22, "z", "toy", _PBNOTE),
    "teddy": Asset(_PB, "pybullet_data/teddy2_VHACD_CHs.obj", _Z, 0.5, "y", "toy",
                   _PBNOTE + "; convex-hull (VHACD) teddy bear"),
    "kiva_pod": Asset(_PB, "pybullet_data/kiva_shelf/meshes/pod_lowres.stl", _Z, 1.0, "y", "furniture",
                      _PBNOTE + "; warehouse shelf pod"),
    "kuka_iiwa": Asset(_PB, "pybullet_data/kuka_iiwa/model.urdf", "BSD-2-Clause", 1.0, "z", "robot",
                       "URDF header: BSD-2-Clause, Krug & Stoyanov, AASS Orebro University"),
    "panda": Asset(_PB, "pybullet_data/franka_panda/panda.urdf", "Apache-2.0", 1.0, "z", "robot",
                   "franka_panda/LICENSE.txt (Apache-2.0)"),
    "r2d2": Asset(_PB, "pybullet_data/r2d2.urdf", _Z, 1.0, "z", "robot", _PBNOTE),
    "husky": Asset(_PB, "pybullet_data/husky/husky.urdf", _Z, 1.0, "z", "robot",
                   _PBNOTE + "; Clearpath Husky UGV model"),
    "racecar": Asset(_PB, "pybullet_data/racecar/racecar.urdf", _Z, 1.0, "z", "vehicle",
                     _PBNOTE + "; 1:10 MIT RACECAR model"),
    "traffic_cone": Asset(_PB, "pybullet_data/racecar/meshes/cone.obj", _Z, 3.0, "z", "street",
                          _PBNOTE + "; the racecar course cone, scaled x3 to a 0.5 m traffic cone"),
    "stone": Asset(_PB, "pybullet_data/stone.obj", _Z, 1.0, "z", "street", _PBNOTE),
    "terrain": Asset(_PB, "pybullet_data/terrain.obj", _Z, 1.0, "z", "ground", _PBNOTE + "; bumpy ground"),
    "monastery": Asset(_PB, "pybullet_data/samurai_monastry.obj", _Z, 1.0, "y", "building",
                       _PBNOTE + "; 125k-triangle temple complex, 124 x 121 m"),
    **{f"object_{k}": Asset(_PB, f"pybullet_data/random_urdfs/{k}/{k}.obj", _Z, 0.015, "z", "clutter",
                            _PBNOTE + "; procedurally generated random object")
       for k in RANDOM_OBJECTS},
}


def assets_available() -> bool:
    """Whether the package that ships the asset meshes (``pybullet``) is installed."""
    return importlib.util.find_spec("pybullet_data") is not None


def asset_root() -> Path:
    """The folder that holds ``pybullet_data`` (found without importing pybullet itself).

    Raises
    ------
    ImportError
        If ``pybullet`` is not installed (``pip install 'depthnormals[assets]'``).
    """
    spec = importlib.util.find_spec("pybullet_data")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("the asset-mesh scenes need the meshes shipped in pybullet: "
                          "pip install 'depthnormals[assets]' (or pip install pybullet); "
                          "`depthnormals synth --scenes procedural` needs neither")
    return Path(next(iter(spec.submodule_search_locations))).parent


def _rot_rpy(rpy) -> np.ndarray:
    r, p, y = (float(a) for a in rpy)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx  # URDF: fixed-axis roll, pitch, yaw


def _floats(text: str) -> list[float]:
    """Three numbers of a URDF attribute; ``$(optenv NAME a b c)`` (xacro left-over) gives a b c."""
    text = text.strip()
    if text.startswith("$(optenv"):
        text = " ".join(text.rstrip(")").split()[2:])
    return [float(v) for v in text.split()]


def _origin(el) -> np.ndarray:
    T = np.eye(4)
    o = el.find("origin") if el is not None else None
    if o is not None:
        T[:3, :3] = _rot_rpy(_floats(o.get("rpy", "0 0 0")))
        T[:3, 3] = _floats(o.get("xyz", "0 0 0"))
    return T


def _read_mesh(path: Path) -> Mesh:
    try:
        import trimesh
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("asset meshes are read with trimesh: pip install 'depthnormals[assets]'") from exc
    m = trimesh.load(path, force="mesh", process=False)
    V = np.asarray(m.vertices, dtype=np.float64)
    F = np.asarray(m.faces, dtype=np.int64)
    if F.ndim != 2 or F.shape[0] == 0:
        raise ValueError(f"{path}: the mesh holds no triangles")
    return V, F


def _geometry(geom, base: Path) -> Mesh | None:
    mesh = geom.find("mesh")
    if mesh is not None:
        name = mesh.get("filename", "").replace("package://", "")
        V, F = _read_mesh(base / name)
        s = np.array([float(v) for v in mesh.get("scale", "1 1 1").split()])
        return V * s, F
    if geom.find("box") is not None:
        sx, sy, sz = (float(v) for v in geom.find("box").get("size").split())
        return box((-sx / 2, -sy / 2, -sz / 2), (sx / 2, sy / 2, sz / 2))
    if geom.find("cylinder") is not None:
        c = geom.find("cylinder")
        r, h = float(c.get("radius")), float(c.get("length"))
        return cylinder((0.0, 0.0, -h / 2), r, h)
    if geom.find("sphere") is not None:
        return icosphere((0.0, 0.0, 0.0), float(geom.find("sphere").get("radius")), level=4)
    return None


def _urdf(path: Path) -> Mesh:
    """A URDF robot at its rest pose (all joints 0): the union of its links' visuals."""
    robot = ET.parse(path).getroot()
    links = {link.get("name"): link for link in robot.findall("link")}
    joints = robot.findall("joint")
    children = {j.find("child").get("link") for j in joints}
    pose = {name: np.eye(4) for name in links if name not in children}  # roots
    pending = list(joints)
    while pending:  # joints may be listed in any order
        left = []
        for j in pending:
            parent, child = j.find("parent").get("link"), j.find("child").get("link")
            if parent in pose:
                pose[child] = pose[parent] @ _origin(j)
            else:
                left.append(j)
        if len(left) == len(pending):
            raise ValueError(f"{path}: joints do not form a tree")
        pending = left
    parts = []
    for name, link in links.items():
        for vis in link.findall("visual"):
            geom = vis.find("geometry")
            m = _geometry(geom, path.parent) if geom is not None else None
            if m is None:
                continue
            T = pose[name] @ _origin(vis)
            parts.append((m[0] @ T[:3, :3].T + T[:3, 3], m[1]))
    return merge(parts)


@functools.lru_cache(maxsize=64)
def _canonical(name: str) -> Mesh:
    a = ASSETS[name]
    path = asset_root() / a.path
    if not path.is_file():
        raise FileNotFoundError(f"asset {name!r}: {path} is missing from the installed {a.package}")
    V, F = _urdf(path) if path.suffix == ".urdf" else _read_mesh(path)
    V = V * a.scale
    if a.up == "y":  # y up -> z up (right-handed: x stays, y -> z, z -> -y)
        V = np.stack([V[:, 0], -V[:, 2], V[:, 1]], axis=1)
    lo, hi = V.min(0), V.max(0)
    V = V - np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    V.setflags(write=False)
    F.setflags(write=False)
    return V, F


def load_asset(name: str, *, height: float | None = None, rotate_z_deg: float = 0.0,
               translate=(0.0, 0.0, 0.0)) -> Mesh:
    """An asset mesh in metres, world z up, standing on ``translate`` (its base centre).

    The mesh is read once per process (cached), scaled by the table's ``scale``, turned to
    z up, centred in x and y with its lowest point at z = 0, then optionally resized to
    ``height`` metres, rotated about z and moved.

    Parameters
    ----------
    name : str
        Key of :data:`ASSETS`.
    height : float, optional, keyword-only
        Resize uniformly so that the mesh is this tall (metres); default: the table's scale.
    rotate_z_deg : float, keyword-only
        Rotation about the vertical axis, degrees.
    translate : (3,) array_like, keyword-only
        Where the base centre goes, metres.

    Returns
    -------
    vertices : ndarray (N, 3) float64
    faces : ndarray (M, 3) int64

    Raises
    ------
    ValueError
        Unknown name or a non-positive height.
    ImportError
        If pybullet (the meshes) or trimesh (the reader) is not installed.
    """
    if name not in ASSETS:
        raise ValueError(f"unknown asset {name!r}; valid: {', '.join(ASSETS)}")
    V, F = _canonical(name)
    if height is not None:
        if not height > 0:
            raise ValueError(f"height must be > 0 metres; got {height!r}")
        V = V * (float(height) / max(float(V[:, 2].max()), 1e-9))
    a = np.radians(rotate_z_deg)
    R = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    return V @ R.T + np.asarray(translate, dtype=np.float64), F.copy()
