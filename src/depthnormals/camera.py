"""Pinhole intrinsics and back-projection (OpenCV frame: x right, y down, z forward)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Union

import numpy as np

from ._validate import check_depth, unmasked

__all__ = ["DISTORTION_LENGTHS", "OPENCV_MODELS", "Intrinsics", "IntrinsicsLike", "as_intrinsics",
           "backproject", "check_distortion", "lens_distortion", "undistort_depth"]


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


#: The lengths of a distortion vector :func:`undistort_depth` reads, in OpenCV's order:
#: ``(k1, k2, p1, p2)``, ``+ (k3,)``, ``+ (k4, k5, k6)`` (the rational model) and ``+ (s1, s2,
#: s3, s4)`` (thin prism).
DISTORTION_LENGTHS = (4, 5, 8, 12)
#: The distortion models (ROS ``distortion_model`` names, lower case) whose coefficients are
#: OpenCV's, which :func:`undistort_depth` undoes: ROS's ``plumb_bob`` and
#: ``rational_polynomial`` and RealSense's ``Brown Conrady``.
OPENCV_MODELS = ("plumb_bob", "rational_polynomial", "brown conrady", "brown_conrady")


def check_distortion(distortion: Any, name: str = "distortion") -> tuple[float, ...]:
    """``distortion`` as a tuple of floats of a length in :data:`DISTORTION_LENGTHS`, all finite
    (ValueError / TypeError naming what was wrong otherwise)."""
    if isinstance(distortion, (str, bytes)) or distortion is None:
        raise TypeError(f"{name} must be a sequence of numbers (k1, k2, p1, p2[, k3[, k4, k5, k6"
                        f"[, s1, s2, s3, s4]]]); got {type(distortion).__name__}")
    try:
        d = np.asarray(distortion, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a sequence of numbers (k1, k2, p1, p2[, k3[, k4, k5, "
                        f"k6[, s1, s2, s3, s4]]]); got {distortion!r}") from exc
    if d.size not in DISTORTION_LENGTHS:
        raise ValueError(f"{name} must hold 4, 5, 8 or 12 coefficients in OpenCV's order (k1, k2, "
                         f"p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4]]]); got {d.size}: "
                         f"{d.tolist()} (the 14-coefficient tilted model is not supported)")
    if not np.all(np.isfinite(d)):
        raise ValueError(f"{name} must be finite; got {d.tolist()}")
    return tuple(float(x) for x in d)


def lens_distortion(distortion: Any, name: str = "distortion") -> tuple[float, ...]:
    """A lens to undo: ``distortion`` checked (:func:`check_distortion`), or () where there is
    nothing to undo (None, an empty sequence, every coefficient 0). The one reading of the
    optional ``distortion`` of camera files, real-sensor folders and the command line."""
    if distortion is None or (isinstance(distortion, (list, tuple)) and not distortion):
        return ()
    d = check_distortion(distortion, name)
    return d if any(d) else ()


@lru_cache(maxsize=4)
def _lens_map(h: int, w: int, cam: Intrinsics, dist: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Where the ray of every pixel of the undistorted (H, W) grid of ``cam`` lands in the
    distorted image (OpenCV's model, :func:`undistort_depth`): the column and row (float64
    (H, W) each, NaN at a pole of the rational model), read-only (they are cached)."""
    k = np.zeros(12)
    k[:len(dist)] = dist
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = k
    x = ((np.arange(w, dtype=np.float64) - cam.cx) / cam.fx)[None, :]
    y = ((np.arange(h, dtype=np.float64) - cam.cy) / cam.fy)[:, None]
    r2 = x * x + y * y
    with np.errstate(divide="ignore", invalid="ignore"):
        radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xy = x * y
    xd = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x) + r2 * (s1 + r2 * s2)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy + r2 * (s3 + r2 * s4)
    us = np.where(np.isfinite(xd), cam.fx * xd + cam.cx, np.nan)
    vs = np.where(np.isfinite(yd), cam.fy * yd + cam.cy, np.nan)
    us.setflags(write=False)
    vs.setflags(write=False)
    return us, vs


@lru_cache(maxsize=4)
def _source_pixels(h: int, w: int, cam: Intrinsics, dist: tuple[float, ...]) -> np.ndarray:
    """For every pixel of the undistorted (H, W) grid of ``cam``, the flat index of the pixel of
    the distorted image nearest to where its ray lands (:func:`_lens_map`), -1 where that lies
    outside: int32 (H, W), read-only (it is cached)."""
    us, vs = _lens_map(h, w, cam, dist)
    with np.errstate(invalid="ignore"):
        uu = np.floor(us + 0.5)
        vv = np.floor(vs + 0.5)
        inside = (uu >= 0) & (uu < w) & (vv >= 0) & (vv < h)  # NaN: outside
    out = np.where(inside, np.where(inside, vv, 0) * w + np.where(inside, uu, 0), -1)
    out = out.astype(np.int32)
    out.setflags(write=False)
    return out


#: ``undistort_depth(interpolation="linear")``: the four depths around the landing point are
#: blended only where the largest is within this share of the smallest (the depth-jump
#: threshold of the uncertainty map's densities); elsewhere the nearest one is taken.
LINEAR_JUMP = 0.03


def undistort_depth(depth: Any, K: Any, distortion: Any, *, interpolation: str = "nearest"
                    ) -> np.ndarray:
    """Resample a depth image from a distorting lens onto the pinhole grid of ``K``.

    Every estimator of this package reads pixel ``(u, v)`` as the ray ``((u - cx) / fx, (v -
    cy) / fy, 1)``: a lens that distorts (a wide time-of-flight lens, an unrectified
    ``image_raw`` stream) bends the planes of a depth image read so, and the normals err by
    degrees towards the image's edges (the Azure Kinect frame of docs/benchmarks.md, section
    25: the default's plane interiors 4.93 deg with the distortion ignored, 2.14 undistorted,
    against the same reference). Each pixel of the output takes the depth where its ray lands
    through the lens (OpenCV's model, as ``cv2.initUndistortRectifyMap`` with ``R`` =
    identity and the same ``K``, then ``cv2.remap``). Planar depth ``z`` is a property of the
    3-D point, so values are carried over, not changed.

    Parameters
    ----------
    depth : array_like, shape (H, W)
        Depth in any unit and dtype (integers keep their codes under ``"nearest"``: an invalid
        code stays one; ``"linear"`` reads 0, negative, NaN and inf as invalid, so mask other
        codes such as 65535 first).
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        The camera matrix of the distorted image (pixels, 0-based pixel centres); the output
        uses the same one.
    distortion : sequence of 4, 5, 8 or 12 floats
        OpenCV's order: ``(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4]]])``; the
        normalised ray ``(x, y)``, ``r^2 = x^2 + y^2``, lands at ``x' = x (1 + k1 r^2 + k2 r^4
        + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2) + s1 r^2 +
        s2 r^4``, ``y' = y (...) + p1 (r^2 + 2 y^2) + 2 p2 x y + s3 r^2 + s4 r^4`` (ROS
        ``plumb_bob`` is the first 5, ``rational_polynomial`` the first 8; the Azure Kinect's
        Brown-Conrady calibration is the rational model). The 14-coefficient tilted model is
        not supported.
    interpolation : {"nearest", "linear"}
        ``"nearest"`` (default; sensor depth): the depth of the nearest input pixel, never a
        blend across a jump. ``"linear"`` (noise-free renders): the bilinear blend of the
        inverse depths of the four input pixels around the landing point (exact on a plane to
        the model's curvature) where all four are valid and within :data:`LINEAR_JUMP` of each
        other, else the nearest; float output. Measured (docs/benchmarks.md section 25): on a
        noise-free distorted plane the default's normals err 10.1 deg mean after
        ``"nearest"`` (its half-pixel jitter reads as relief) and 0.002 after ``"linear"``; on
        the same plane with 2 mm noise and millimetre steps 0.36 after ``"nearest"`` and 2.09
        after ``"linear"`` (the blend makes the noise uneven); on the real Azure Kinect frame
        2.14 / 2.20 deg on plane interiors.

    Returns
    -------
    ndarray, shape (H, W)
        The depth on the pinhole grid (``"nearest"``: the dtype of ``depth``; ``"linear"``:
        float32 for float32 or integer depth, else float64); pixels whose ray leaves the input
        image, or lands on invalid depth, are invalid (0 for integer output, NaN for float).

    Raises
    ------
    ValueError, TypeError
        A depth that is not a non-empty 2-D real array, a distortion of another length or
        with non-finite values, an unknown interpolation.

    Examples
    --------
    A lens with ``k1 > 0`` bends the rays outward: the outer columns' rays land outside the
    recorded image (NaN), the inner ones on their own pixels at this size.

    >>> d = np.arange(1.0, 21.0).reshape(4, 5)
    >>> undistort_depth(d, (2.0, 2.0, 2.0, 1.5), (0.3, 0.0, 0.0, 0.0))[:2].tolist()
    [[nan, 2.0, 3.0, 4.0, nan], [nan, 7.0, 8.0, 9.0, nan]]
    """
    arr = unmasked(depth)
    arr = arr if isinstance(arr, np.ndarray) else np.asarray(arr)
    if arr.dtype == bool or arr.dtype.kind not in "iuf":
        raise TypeError(f"depth must hold real numbers; got dtype {arr.dtype}")
    if arr.ndim == 3 and arr.shape[-1] == 1:
        arr = arr[..., 0]
    if arr.ndim != 2 or arr.size == 0:
        raise ValueError(f"depth must be a non-empty 2-D array (H, W); got shape {arr.shape}")
    if interpolation not in ("nearest", "linear"):
        raise ValueError(f"interpolation must be 'nearest' or 'linear'; got {interpolation!r}")
    cam = as_intrinsics(K)
    dist = check_distortion(distortion)
    h, w = arr.shape
    if interpolation == "linear":
        out_dtype = np.float64 if arr.dtype == np.float64 else np.float32
        if not any(dist):
            return arr.astype(out_dtype)
        return _linear(arr, cam, dist).astype(out_dtype)
    if not any(dist):
        return arr.copy()
    idx = _source_pixels(h, w, cam, dist)
    fill = arr.dtype.type(np.nan) if arr.dtype.kind == "f" else arr.dtype.type(0)
    flat = np.ascontiguousarray(arr).reshape(-1)
    return np.where(idx >= 0, flat[np.maximum(idx, 0)], fill)


def _linear(arr: np.ndarray, cam: Intrinsics, dist: tuple[float, ...]) -> np.ndarray:
    """``undistort_depth(..., interpolation="linear")`` (float64; NaN invalid)."""
    h, w = arr.shape
    us, vs = _lens_map(h, w, cam, dist)
    z = arr.astype(np.float64)
    z = np.where(np.isfinite(z) & (z > 0), z, np.nan)
    near = undistort_depth(z, cam, dist)
    with np.errstate(invalid="ignore"):
        inside = (us >= 0) & (us <= w - 1) & (vs >= 0) & (vs <= h - 1)
    u0 = np.clip(np.floor(np.where(inside, us, 0)), 0, max(w - 2, 0)).astype(np.intp)
    v0 = np.clip(np.floor(np.where(inside, vs, 0)), 0, max(h - 2, 0)).astype(np.intp)
    u1 = np.minimum(u0 + 1, w - 1)
    v1 = np.minimum(v0 + 1, h - 1)
    a = np.where(inside, us, 0) - u0
    b = np.where(inside, vs, 0) - v0
    q = (z[v0, u0], z[v0, u1], z[v1, u0], z[v1, u1])
    with np.errstate(invalid="ignore", divide="ignore"):
        lo = np.minimum(np.minimum(q[0], q[1]), np.minimum(q[2], q[3]))
        hi = np.maximum(np.maximum(q[0], q[1]), np.maximum(q[2], q[3]))
        smooth = inside & (hi - lo <= LINEAR_JUMP * lo)  # NaN anywhere: False
        iz = ((1 - a) * (1 - b) / q[0] + a * (1 - b) / q[1] + (1 - a) * b / q[2]
              + a * b / q[3])
        return np.where(smooth, 1.0 / iz, near)
