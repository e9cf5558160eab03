"""Shared input checkers: always on, and each message says what to pass instead."""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np

__all__ = ["NoValidNormalWarning", "check_choice", "check_depth", "check_int", "check_normals",
           "check_positive", "check_real", "no_valid_normal_message"]


class NoValidNormalWarning(RuntimeWarning):
    """The output holds no finite normal (every pixel NaN).

    One policy for all-NaN output (docs/conventions.md, "Errors and exit status"): the API
    returns the all-NaN array and warns with this category; the command line writes it and
    exits with status 3. It happens when no depth pixel is valid (all 0, negative, NaN or
    inf: often a missing ``depth_scale`` or a wrong file), when no valid pixel has a valid
    neighbour (a 1x1 image, isolated points), and when the method's own rules refuse every
    neighbourhood (PCL's depth-change limit on depth that jumps between all neighbours); the
    message says which.
    """


def no_valid_normal_message(depth: np.ndarray, what: str = "the depth") -> str:
    """Why an output holds no finite normal, for :class:`NoValidNormalWarning` and the CLI."""
    ok = np.isfinite(depth) & (depth > 0)
    valid = int(np.count_nonzero(ok))
    if valid == 0:
        return (f"no pixel of {what} holds a valid depth (all are 0, negative, NaN or inf), so "
                "every normal is NaN; check the file, the depth scale and the image shape")
    paired = np.zeros(ok.shape, dtype=bool)  # valid pixels with a valid 4-neighbour
    if ok.ndim == 2:
        across = ok[:, 1:] & ok[:, :-1]
        down = ok[1:] & ok[:-1]
        paired[:, 1:] |= across
        paired[:, :-1] |= across
        paired[1:] |= down
        paired[:-1] |= down
    shape = f"{depth.shape[0]} x {depth.shape[1]} pixels"
    if not paired.any():
        return (f"{what} has {valid} valid pixel(s) of {depth.size}, but none has a valid "
                f"neighbour ({shape}), so every normal is NaN")
    return (f"{what} has {valid} valid pixel(s) of {depth.size}, {int(paired.sum())} with a valid "
            f"neighbour ({shape}), but the method's own rules refused every neighbourhood (a "
            "depth-change limit, as PCL's, where the depth jumps between neighbours everywhere; "
            "too few valid pixels in its windows), so every normal is NaN")


def check_positive(value: Any, name: str, *, allow_none: bool = False) -> float | None:
    """Return ``value`` as a finite positive float, or raise ValueError/TypeError."""
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a positive real number; got {type(value).__name__}")
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be finite and > 0; got {value!r}")
    return value


def _bounds(minimum: float, maximum: float) -> str:
    if maximum == math.inf:
        return f">= {minimum:g}"
    return f"in [{minimum:g}, {maximum:g}]"


def check_real(value: Any, name: str, *, minimum: float = -math.inf, maximum: float = math.inf,
               finite: bool = True, hint: str = "") -> float:
    """Return ``value`` as a float in ``[minimum, maximum]`` (and finite unless ``finite`` is
    False), else raise TypeError (not a real number) or ValueError (out of range). ``hint`` is
    added to the message (e.g. the default a user may want)."""
    where = _bounds(minimum, maximum) + (f" ({hint})" if hint else "")
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number {where}; got {type(value).__name__}")
    value = float(value)
    if (finite and not math.isfinite(value)) or not minimum <= value <= maximum:
        raise ValueError(f"{name} must be {'finite and ' if finite else ''}{where}; got {value!r}")
    return value


def check_int(value: Any, name: str, *, minimum: int, maximum: int) -> int:
    """Return ``value`` as an int in ``minimum..maximum``, else raise TypeError (not an
    integer; bools are refused) or ValueError (out of range)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer in {minimum}..{maximum}; got {value!r}")
    if not minimum <= int(value) <= maximum:
        raise ValueError(f"{name} must be in {minimum}..{maximum}; got {value}")
    return int(value)


def check_choice(value: Any, name: str, choices: tuple[str, ...] | list[str]) -> str:
    """Return ``value`` if it is one of ``choices`` (strings), else raise ValueError listing them."""
    if not isinstance(value, str):
        raise TypeError(f"{name} must be a string, one of {sorted(choices)}; got {value!r}")
    if value not in choices:
        raise ValueError(f"unknown {name} {value!r}; valid choices: {', '.join(choices)}")
    return value


def unmasked(depth: Any) -> Any:
    """A numpy masked array as a plain one whose masked pixels are invalid depth (NaN, 0 for
    integers), so the mask is honoured rather than dropped (``np.asarray`` keeps the values
    under the mask); anything else as it is."""
    if isinstance(depth, np.ma.MaskedArray):
        fill = 0 if depth.dtype.kind in "iub" else np.nan
        return depth.filled(fill) if depth.dtype.kind in "iufb" else np.asarray(depth)
    return depth


def check_depth(depth: Any, *, depth_scale: float | None = None, name: str = "depth") -> np.ndarray:
    """Validate a depth map and return it as a native-endian, C-contiguous float array.

    float32 and float64 are preserved (float16 becomes float32, extended precision float64);
    integer depth needs an explicit ``depth_scale`` (metres per unit, e.g. 0.001 for
    millimetres) and becomes float32. Invalid values (0, negative, NaN, inf) are kept as they
    are: estimators mask them; so are the masked pixels of a numpy masked array (:func:`unmasked`).
    A single-channel image ``(H, W, 1)`` is taken as its one channel ``(H, W)``; any other
    3-D shape is refused (``(H, W, 3)`` / ``(H, W, 4)`` named as a colour image).
    """
    if isinstance(depth, (str, bytes)) or depth is None:
        raise TypeError(f"{name} must be a 2-D numeric array (H, W); got {type(depth).__name__}")
    depth = unmasked(depth)
    arr = depth if isinstance(depth, np.ndarray) else np.asarray(depth)
    if arr.dtype == bool or arr.dtype.kind not in "iuf":
        raise TypeError(
            f"{name} must hold real numbers (float32/float64, or integers with depth_scale); "
            f"got dtype {arr.dtype}"
        )
    if arr.ndim == 3 and arr.shape[-1] == 1:  # a single-channel image (H, W, 1): its one channel
        arr = arr[..., 0]
    if arr.ndim != 2:
        hint = ""
        if arr.ndim == 3 and arr.shape[-1] in (3, 4):
            hint = (f": {arr.shape[-1]} channels, a colour image rather than a depth map; pass "
                    "the depth image itself")
        raise ValueError(f"{name} must be a 2-D array (H, W) or (H, W, 1); got shape {arr.shape}{hint}")
    if arr.size == 0:
        raise ValueError(f"{name} is empty (shape {arr.shape}); it needs at least one pixel")
    scale = check_positive(depth_scale, "depth_scale", allow_none=True)
    if arr.dtype.kind in "iu":
        if scale is None:
            raise TypeError(
                f"{name} has integer dtype {arr.dtype}; pass depth_scale (metres per unit, "
                "e.g. depth_scale=0.001 for millimetres) so nothing is rescaled silently"
            )
        return np.ascontiguousarray(arr.astype(np.float64) * scale, dtype=np.float32)
    if arr.dtype.itemsize < 4:
        arr = arr.astype(np.float32)
    elif arr.dtype.itemsize > 8:  # extended precision (np.longdouble): the kernels take float64
        arr = arr.astype(np.float64)
    dtype = arr.dtype.newbyteorder("=")
    out = np.ascontiguousarray(arr, dtype=dtype)
    if scale is not None and scale != 1.0:
        out = out * out.dtype.type(scale)
    return out


def check_normals(normals: Any, *, name: str = "normals",
                  shape: tuple[int, int] | None = None) -> np.ndarray:
    """Validate a normal map (H, W, 3) of real numbers; return it as a float array."""
    arr = normals if isinstance(normals, np.ndarray) else np.asarray(normals)
    if arr.dtype == bool or arr.dtype.kind not in "iuf":
        raise TypeError(f"{name} must be a real (H, W, 3) array; got dtype {arr.dtype}")
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise ValueError(f"{name} must have shape (H, W, 3); got {arr.shape}")
    if arr.size == 0:
        raise ValueError(f"{name} is empty (shape {arr.shape})")
    if shape is not None and arr.shape[:2] != tuple(shape):
        raise ValueError(
            f"{name} has size {arr.shape[:2]} but the other map has size {tuple(shape)}; they must match")
    return arr
