"""Pinhole intrinsics and back-projection (OpenCV frame: x right, y down, z forward)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Union

import numpy as np

from ._validate import check_depth

__all__ = ["Intrinsics", "IntrinsicsLike", "as_intrinsics", "backproject"]


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole camera intrinsics in pixels, pixel centres on integers (0-based).

    Parameters
    ----------
    fx, fy : float
        Focal lengths in pixels, > 0.
    cx, cy : float
        Principal point in pixels on the 0-based integer grid: the pixel at row ``v``,
        column ``u`` samples the ray through ``((u - cx) / fx, (v - cy) / fy, 1)``.

    Examples
    --------
    >>> K = Intrinsics(500.0, 500.0, 319.5, 239.5)
    >>> Intrinsics.from_matrix(K.matrix) == K
    True
    """

    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self) -> None:
        for name in ("fx", "fy", "cx", "cy"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise TypeError(f"intrinsics {name} must be a real number; got {type(value).__name__}")
            if not np.isfinite(value):
                raise ValueError(f"intrinsics {name} must be finite; got {value!r}")
            object.__setattr__(self, name, float(value))
        if self.fx <= 0 or self.fy <= 0:
            raise ValueError(f"focal lengths must be > 0; got fx={self.fx}, fy={self.fy}")

    @classmethod
    def from_matrix(cls, K: Any) -> Intrinsics:
        """Build from a 3x3 camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``."""
        M = np.asarray(K, dtype=np.float64)
        if M.shape != (3, 3):
            raise ValueError(f"K must be a 3x3 matrix (or fx, fy, cx, cy); got shape {M.shape}")
        if not np.all(np.isfinite(M)):
            raise ValueError("K must hold finite numbers")
        if M[0, 1] != 0 or M[1, 0] != 0 or M[2, 0] != 0 or M[2, 1] != 0 or M[2, 2] != 1:
            raise ValueError(
                "K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew, last row 0 0 1); "
                f"got {M.tolist()}"
            )
        return cls(M[0, 0], M[1, 1], M[0, 2], M[1, 2])

    @property
    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix (float64)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def scaled(self, factor: float) -> Intrinsics:
        """Intrinsics of the image resized by ``factor`` (pixel centres on integers kept)."""
        return Intrinsics(self.fx * factor, self.fy * factor,
                          (self.cx + 0.5) * factor - 0.5, (self.cy + 0.5) * factor - 0.5)


IntrinsicsLike = Union[Intrinsics, np.ndarray, Sequence[float], Mapping[str, float]]  # noqa: UP007


def as_intrinsics(K: Any) -> Intrinsics:
    """Accept any of the camera descriptions below and return an :class:`Intrinsics`.

    - an :class:`Intrinsics`;
    - a 3x3 matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (no skew);
    - a 3x4 projection matrix ``P = [[fx, 0, cx, Tx], [0, fy, cy, Ty], [0, 0, 1, 0]]`` (ROS
      ``camera_info``'s P of a rectified camera: its left 3x3 block; ``Tx, Ty``, the stereo
      baseline terms, do not change the pixel rays and are ignored);
    - ``(fx, fy, cx, cy)`` or a mapping with those keys;
    - an Open3D ``PinholeCameraIntrinsic`` (any object with an ``intrinsic_matrix``
      attribute holding the 3x3 matrix; Open3D's pixel grid is 0-based like ours).

    Raises ValueError for a wrong shape, skew, non-finite values or focal lengths <= 0, and
    TypeError for anything else.
    """
    if isinstance(K, Intrinsics):
        return K
    if isinstance(K, Mapping):
        missing = [k for k in ("fx", "fy", "cx", "cy") if k not in K]
        if missing:
            raise ValueError(f"intrinsics mapping lacks {missing}; it needs fx, fy, cx, cy")
        return Intrinsics(K["fx"], K["fy"], K["cx"], K["cy"])
    if K is None or isinstance(K, (str, bytes)):
        raise TypeError(
            "K must be an Intrinsics, a 3x3 matrix, a 3x4 projection matrix, (fx, fy, cx, cy), a "
            f"mapping or an Open3D PinholeCameraIntrinsic; got {type(K).__name__}"
        )
    if not isinstance(K, (np.ndarray, list, tuple)) and hasattr(K, "intrinsic_matrix"):
        return Intrinsics.from_matrix(np.asarray(K.intrinsic_matrix, dtype=np.float64))  # Open3D
    raw = np.asarray(K)
    mixed = not isinstance(K, np.ndarray) and any(
        isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.integer, np.floating))
        for x in np.asarray(K, dtype=object).ravel()
    )
    if mixed or raw.dtype == bool or raw.dtype.kind not in "iuf":
        raise TypeError(
            "K must hold real numbers (a 3x3 matrix, a 3x4 projection matrix or fx, fy, cx, cy); "
            f"got dtype {raw.dtype} from {K!r}"
        )
    M = raw.astype(np.float64)
    if M.shape == (4,):
        return Intrinsics(*M.tolist())
    if M.shape == (3, 3):
        return Intrinsics.from_matrix(M)
    if M.shape == (3, 4):
        try:
            if M[2, 3] != 0 or not np.all(np.isfinite(M[:, 3])):
                raise ValueError("its last row must be [0, 0, 1, 0] and its values finite")
            return Intrinsics.from_matrix(M[:, :3])
        except ValueError as exc:
            raise ValueError(f"K must be a 3x3 matrix, or a 3x4 projection matrix [[fx, 0, cx, Tx], "
                             f"[0, fy, cy, Ty], [0, 0, 1, 0]]; the 3x4 {M.tolist()} is not one: "
                             f"{exc}") from exc
    raise ValueError(f"K must be a 3x3 matrix, a 3x4 projection matrix or (fx, fy, cx, cy); got shape "
                     f"{M.shape}")


def backproject(depth: Any, K: Any, *, depth_scale: float | None = None) -> np.ndarray:
    """Back-project planar depth to camera-frame points.

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Planar depth z (metres, or any unit: the output has the same unit). Invalid
        depth (0, negative, NaN, inf) gives NaN points.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Camera intrinsics, 0-based pixel centres.
    depth_scale : float, optional
        Metres per unit for integer depth.

    Returns
    -------
    points : ndarray, shape (H, W, 3), float64
        ``X = (u - cx) z / fx``, ``Y = (v - cy) z / fy``, ``Z = z``.

    Examples
    --------
    >>> backproject([[2.0]], (1.0, 1.0, 0.0, 0.0))[0, 0].tolist()
    [0.0, 0.0, 2.0]
    """
    z = check_depth(depth, depth_scale=depth_scale).astype(np.float64)
    cam = as_intrinsics(K)
    z = np.where(np.isfinite(z) & (z > 0), z, np.nan)
    h, w = z.shape
    u = np.arange(w, dtype=np.float64)[None, :]
    v = np.arange(h, dtype=np.float64)[:, None]
    return np.stack([(u - cam.cx) * z / cam.fx, (v - cam.cy) * z / cam.fy, z], axis=-1)
