"""Reading depth and intrinsics, writing normals; every write is atomic.

Normal maps as 16-bit PNG (``write_normals(..., ".png")``): channels (R, G, B) = (nx, ny, nz)
encoded as ``round((n + 1) / 2 * 65535)``; invalid (NaN) pixels are written (0, 0, 0), which
no unit vector encodes (it would decode to (-1, -1, -1)). :func:`read_normals` inverts this,
renormalises, and gives NaN for (0, 0, 0).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import struct
import tempfile
import zlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._png import decode_png, encode_png, read_png
from ._validate import check_depth, check_normals, check_positive
from .camera import OPENCV_MODELS, Intrinsics, as_intrinsics, lens_distortion

__all__ = [
    "OUTPUT_SUFFIXES",
    "VIS_CONVENTIONS",
    "CameraFile",
    "atomic_write",
    "normals_to_rgb8",
    "not_depth_reason",
    "read_camera_file",
    "read_depth",
    "read_intrinsics",
    "read_normals",
    "read_npy",
    "read_pgm",
    "to_open3d",
    "write_bytes_atomic",
    "write_normals",
    "write_ply",
    "write_png",
]

DEPTH_SUFFIXES = (".npy", ".png", ".tif", ".tiff", ".bin", ".pgm")
#: Colourings of the 8-bit ``.vis.png`` picture (:func:`normals_to_rgb8`).
VIS_CONVENTIONS = ("3f2n", "open3d")
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_IEND = b"\x00\x00\x00\x00IEND\xaeB`\x82"
#: Larger depth images than this many pixels are refused (a corrupt header, not a sensor).
MAX_PIXELS = 1 << 28


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "wb") -> Iterator[Any]:
    """Open a temporary file beside ``path``; on success it replaces ``path`` atomically.

    On any exception the temporary file is removed and ``path`` is left as it was, so a
    crash never leaves a half-written file under the final name.
    """
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise FileNotFoundError(f"output folder {parent} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=parent)
    try:
        # mkstemp creates 0600; give the file the permissions a plain open() would have
        os.chmod(tmp, 0o666 & ~_umask())
        with os.fdopen(fd, mode) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_write(path) as fh:
        fh.write(data)


def write_png(path: str | Path, img: np.ndarray) -> None:
    """Write a uint8/uint16 image as PNG, atomically."""
    write_bytes_atomic(path, encode_png(img))


def read_depth(path: str | Path, *, depth_scale: float | None = None,
               shape: tuple[int, int] | None = None, invalid: Sequence[float] = (),
               max_depth: float | None = None) -> np.ndarray:
    """Read a depth map.

    Parameters
    ----------
    path : str or Path
        ``.npy`` (float or integer array, (H, W) or (H, W, 1)), ``.png`` (16-bit grey; needs
        ``depth_scale``), ``.pgm`` (binary P5, 8- or 16-bit big-endian as NYU's raw frames;
        needs ``depth_scale``), ``.tif``/``.tiff`` (float32, needs the ``tifffile`` package:
        ``pip install depthnormals[io]``) or ``.bin`` (3F2N format: raw little-endian float32).
    depth_scale : float, optional
        Metres per unit, required for integer data (e.g. 0.001 for millimetre PNGs).
    shape : (H, W), optional
        Size of a ``.bin`` file; default 480 x 640 as in the 3F2N dataset.
    invalid : sequence of numbers, optional
        Raw values (before ``depth_scale``) that mark invalid pixels, e.g. ``(65535,)`` or
        Kinect v1's ``2047``: they become NaN.
    max_depth : float, optional
        Depth beyond this many metres (after scaling) becomes NaN (invalid).

    Returns
    -------
    depth : ndarray, shape (H, W), float32 or float64

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        A corrupt or truncated file, a colour image, a wrong shape, or a bad option; the
        message names the file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"depth file {path} does not exist")
    suffix = path.suffix.lower()
    if suffix == ".npy":
        arr = read_npy(path)
    elif suffix == ".png":
        try:
            data = path.read_bytes()
            if data[:8] == _PNG_SIGNATURE and _PNG_IEND not in data[-24:]:
                raise ValueError("it is truncated (no IEND chunk at its end)")
            arr = decode_png(data, name=str(path))
        except (ValueError, struct.error, IndexError, zlib.error, MemoryError) as exc:
            raise ValueError(f"{path} is not a readable PNG: {_reason(exc, path)}") from exc
    elif suffix == ".pgm":
        arr = _read_pgm(path)
    elif suffix in (".tif", ".tiff"):
        try:
            import tifffile
        except ImportError as exc:
            raise ImportError("reading TIFF depth needs tifffile: pip install 'depthnormals[io]'") from exc
        try:
            arr = tifffile.imread(path)
        except Exception as exc:  # tifffile raises many kinds on a corrupt file
            raise ValueError(f"{path} is not a readable TIFF: {exc}") from exc
    elif suffix == ".bin":
        h, w = shape if shape is not None else (480, 640)
        arr = np.fromfile(path, dtype="<f4")
        if arr.size != h * w:
            raise ValueError(f"{path} holds {arr.size} float32 values; expected {h} x {w} = {h * w} "
                             "(pass shape=(H, W))")
        arr = arr.reshape(h, w)
    else:
        raise ValueError(f"{path}: unknown depth format {suffix!r}; use one of {', '.join(DEPTH_SUFFIXES)}")
    if arr.ndim == 3 and arr.shape[-1] == 1:
        arr = arr[..., 0]
    if arr.ndim != 2:
        what = (f"a colour image ({arr.shape[-1]} channels)" if arr.ndim == 3 and arr.shape[-1] in (2, 3, 4)
                else f"{arr.ndim} dimensions")
        raise ValueError(f"{path} holds an array of shape {arr.shape}, {what}, not a single-channel "
                         "depth image (H, W); pass the depth image itself")
    bad = None
    if len(invalid):
        codes = np.asarray([_finite(c, "invalid") for c in invalid])
        if arr.dtype.kind in "iu":  # only the codes this integer type can hold (no wrap-around)
            info = np.iinfo(arr.dtype)
            codes = codes[(codes == np.round(codes)) & (codes >= info.min) & (codes <= info.max)]
            codes = codes.astype(arr.dtype)
        bad = np.isin(arr, codes)
    z = check_depth(arr, depth_scale=depth_scale, name=f"depth in {path}")
    if bad is not None and bad.any():
        z = z if z is not arr else z.copy()
        z[bad] = np.nan
    if max_depth is not None:
        limit = check_positive(max_depth, "max_depth")
        with np.errstate(invalid="ignore"):
            far = z > limit
        if far.any():
            z = z if z is not arr else z.copy()
            z[far] = np.nan
    return z


def _reason(exc: BaseException, path: Path) -> str:
    text = str(exc) or type(exc).__name__
    return text.replace(f"{path} ", "").replace(str(path), "").strip() or type(exc).__name__


def _finite(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} values must be numbers; got {value!r}")
    if not math.isfinite(float(value)) and not math.isnan(float(value)):
        raise ValueError(f"{name} values must be finite numbers or NaN; got {value!r}")
    return float(value)


def _npy_header(path: Path) -> tuple[tuple[int, ...], np.dtype]:
    """Shape and dtype of a ``.npy`` file from its header; ValueError naming the file when the
    header is corrupt or the data is shorter than the header says."""
    try:
        with open(path, "rb") as fh:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
            else:
                shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
            offset = fh.tell()
    except Exception as exc:  # a corrupt header fails in numpy's parser in many ways
        raise ValueError(f"{path} is not a readable .npy file: {exc or type(exc).__name__}") from exc
    if dtype.hasobject:
        raise ValueError(f"{path} holds Python objects (dtype {dtype}); a depth .npy holds numbers")
    count = math.prod(shape)
    need = offset + count * dtype.itemsize
    size = path.stat().st_size
    if size < need:
        raise ValueError(f"{path} is truncated: its header says {shape} {dtype} ({need} bytes), the "
                         f"file has {size} bytes")
    return shape, dtype


def read_npy(path: str | Path) -> np.ndarray:
    """A ``.npy`` file of numbers, checked before it is read.

    Parameters
    ----------
    path : str or Path
        The file.

    Returns
    -------
    ndarray
        Its array (at most :data:`MAX_PIXELS` values; no Python objects).

    Raises
    ------
    ValueError
        Naming the file, when its header is corrupt, its data shorter than the header says
        (a truncated copy), it holds Python objects or more than :data:`MAX_PIXELS` values.
    """
    path = Path(path)
    shape, _ = _npy_header(path)
    if math.prod(shape) > MAX_PIXELS:
        raise ValueError(f"{path} holds shape {shape}: more than {MAX_PIXELS} values, not a depth image")
    try:
        return np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise ValueError(f"{path} is not a readable .npy file: {exc}") from exc


def read_pgm(path: str | Path, *, byteorder: str = ">") -> np.ndarray:
    """Read a binary (P5) or ASCII (P2) PGM: uint8 (maxval < 256) or uint16 (H, W).

    Parameters
    ----------
    path : str or Path
        The file.
    byteorder : {">", "<"}, default ">"
        Byte order of 16-bit binary samples (maxval > 255). The PGM specification says
        big-endian (``">"``, as NYU v2's registered frames); the NYU v2 raw disparity frames
        are little-endian (``"<"``) behind the same header.

    Returns
    -------
    ndarray (H, W), uint8 or uint16

    Raises
    ------
    ValueError
        Naming the file: not a PGM, a truncated or malformed header, too few samples, a size
        larger than any depth image.
    """
    if byteorder not in (">", "<"):
        raise ValueError(f"byteorder must be '>' (big-endian, the PGM standard) or '<'; "
                         f"got {byteorder!r}")
    path = Path(path)
    data = path.read_bytes()
    if data[:2] not in (b"P5", b"P2"):
        raise ValueError(f"{path} is not a PGM (magic {data[:2]!r}; expected P5 or P2)")
    fields: list[bytes] = []
    pos = 0
    while len(fields) < 4:
        while pos < len(data) and data[pos:pos + 1].isspace():
            pos += 1
        if data[pos:pos + 1] == b"#":
            while pos < len(data) and data[pos:pos + 1] not in (b"\n", b"\r"):
                pos += 1
            continue
        start = pos
        while pos < len(data) and not data[pos:pos + 1].isspace() and data[pos:pos + 1] != b"#":
            pos += 1
        if start == pos:
            raise ValueError(f"{path} is not a readable PGM: the header is truncated")
        fields.append(data[start:pos])
    pos += 1  # the single whitespace after maxval
    try:
        w, h, maxval = (int(x) for x in fields[1:])
    except ValueError as exc:
        raise ValueError(f"{path} is not a readable PGM: bad header {b' '.join(fields[1:])!r}") from exc
    if w < 1 or h < 1 or not 0 < maxval < 65536:
        raise ValueError(f"{path} is not a readable PGM: size {w} x {h}, maxval {maxval}")
    if w * h > MAX_PIXELS:
        raise ValueError(f"{path}: a {w} x {h} PGM is larger than any depth image")
    out = np.uint16 if maxval > 255 else np.uint8
    if fields[0] == b"P2":
        values = np.array(data[pos:].split()[: w * h], dtype=np.int64)
        if values.size != w * h:
            raise ValueError(f"{path} is truncated: {values.size} samples for a {w} x {h} PGM")
        return values.reshape(h, w).astype(out)
    dtype = np.dtype(byteorder + "u2") if maxval > 255 else np.dtype("u1")
    need = w * h * dtype.itemsize
    if len(data) - pos < need:
        raise ValueError(f"{path} is truncated: {w} x {h} pixels need {need} bytes, it has {len(data) - pos}")
    return np.frombuffer(data, dtype=dtype, count=w * h, offset=pos).reshape(h, w).astype(out)


def _read_pgm(path: Path) -> np.ndarray:
    """A PGM as :func:`read_depth` reads it: the standard's big-endian 16-bit samples."""
    return read_pgm(path)


def not_depth_reason(path: str | Path) -> str | None:
    """Why a file with a depth suffix is not a depth image, from its header alone, or None.

    What a folder run (``depthnormals estimate FOLDER``) uses to skip the colour PNGs and
    ``.npy`` arrays that often sit beside depth images: a colour PNG (RGB, RGBA, palette)
    or an array that is not (H, W) / (H, W, 1). Unreadable files return None here: reading
    them raises the error that names them.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    try:
        if suffix == ".png":
            with open(path, "rb") as fh:
                head = fh.read(33)
            if len(head) < 26 or head[12:16] != b"IHDR":
                return None
            ctype = head[25]
            names = {2: "RGB", 3: "palette", 4: "grey + alpha", 6: "RGBA"}
            return f"a colour image ({names[ctype]} PNG)" if ctype in names else None
        if suffix == ".npy":
            shape, dtype = _npy_header(path)
            if len(shape) == 2 or (len(shape) == 3 and shape[-1] == 1):
                return None if dtype.kind in "iuf" else f"an array of {dtype}, not depth"
            return f"an array of shape {shape}, not a depth image (H, W)"
    except (OSError, ValueError):
        return None
    return None

@dataclass(frozen=True)
class CameraFile:
    """What a camera file says: the intrinsics, and what it may add about the depth images.

    Attributes
    ----------
    K : Intrinsics
        The camera (0-based pixel centres).
    depth_scale : float or None
        Metres per unit of the integer depth images (key ``depth_scale``).
    invalid : tuple of float
        Raw depth values that mark invalid pixels (key ``invalid``, or ``invalid_value`` as
        the real-sensor folder reader spells it; a number or a list, e.g. ``[65535]`` or
        ``[0, 2047]``), compared before scaling.
    max_depth : float or None
        Depth beyond this many metres is invalid (key ``max_depth``).
    source : Path
        The file read (the text itself, as a Path, for a camera given inline).
    encoding : str or None
        How raw values become depth (key ``encoding``): ``"linear"`` (``value * depth_scale``)
        or a name a dataset reader knows (``"nyu_raw_disparity"``, ...); None when the file
        does not say. :func:`read_depth` reads linear depth only.
    raw_format : str or None
        The free-text ``raw_format`` note of a real-sensor folder's ``intrinsics.json``
        (:func:`depthnormals.datasets.realsensors.encoding_of` reads an encoding from it).
    distortion : tuple of float
        The lens's distortion in OpenCV's order (key ``distortion``: ``[k1, k2, p1, p2[, k3[,
        k4, k5, k6[, s1, s2, s3, s4]]]]``; () when absent or all 0): the command line
        resamples each depth image onto the pinhole grid of ``K`` first
        (:func:`depthnormals.undistort_depth`).
    ros_distortion : tuple of float
        A ROS ``camera_info``'s non-zero ``D`` (``D`` / ``d`` / ``distortion_coefficients``,
        of one of OpenCV's models, :data:`depthnormals.camera.OPENCV_MODELS`), which is **not**
        applied: ROS depth topics are taken as rectified (``image_rect``); the command line
        says so and names ``--distortion`` for an ``image_raw`` stream. () when absent, all 0,
        or of another model.
    ros_other_lens : str
        The ``distortion_model`` of a ROS ``camera_info`` whose non-zero ``D`` is of a model
        :func:`depthnormals.undistort_depth` cannot undo (``equidistant``, a fisheye) or does
        not read as OpenCV's coefficients; "" otherwise. Not applied either: the command line
        says so (rectify an ``image_raw`` stream first).
    """

    K: Intrinsics
    depth_scale: float | None = None
    invalid: tuple[float, ...] = ()
    max_depth: float | None = None
    source: Path | None = None
    encoding: str | None = None
    raw_format: str | None = None
    distortion: tuple[float, ...] = ()
    ros_distortion: tuple[float, ...] = ()
    ros_other_lens: str = ""


def read_camera_file(path: str | Path) -> CameraFile:
    """Read a camera file: intrinsics, and optionally the depth scale and invalid codes.

    The formats, told apart by suffix and content:

    - JSON or YAML with ``fx, fy, cx, cy`` (pixels, 0-based), ``K`` / ``k`` (3x3, nested or
      flat), or ``P`` / ``p`` (3x4 projection), optionally under a ``camera`` or
      ``intrinsics`` key; beside them, optional ``depth_scale`` (metres per unit),
      ``invalid`` (or ``invalid_value``: raw values, e.g. ``[0, 65535]``), ``max_depth``
      (metres), ``encoding`` (``"linear"`` unless a dataset reader says otherwise) and
      ``distortion`` (the lens's, OpenCV's order: :func:`depthnormals.undistort_depth`).
    - ROS ``camera_info`` YAML (``camera_calibration_parsers``: ``camera_matrix: {rows: 3,
      cols: 3, data: [...]}``, else ``projection_matrix``), and a ``camera_info`` message
      as ``rostopic echo`` / ``ros2 topic echo`` print it (``K: [...]`` / ``k: [...]``).
      Its distortion coefficients are not applied (the depth is taken as rectified,
      ``image_rect``); non-zero ones are kept in ``ros_distortion`` so the command line
      can say so.
    - Open3D's ``PinholeCameraIntrinsic`` JSON (``intrinsic_matrix``, 9 values, column-major,
      as ``open3d.io.write_pinhole_camera_intrinsic`` writes it).
    - Text (``.txt``): 9 numbers are a 3x3 ``K``, 12 a 3x4 ``P`` (row-major), 4 or 5 the 3F2N
      dataset's ``params.txt`` (``fx fy cx cy [N]`` on MATLAB's 1-based grid: 1 is
      subtracted from ``cx, cy``).
    - No file of that name: four comma-separated numbers ``fx,fy,cx,cy`` are the camera
      itself (pixels, 0-based), as the command line's ``-K 525,525,319.5,239.5``.

    This is the one reader of camera files; dataset readers with such a file (e.g. a folder
    of depth images beside an ``intrinsics.json``) can call it too.

    Returns
    -------
    CameraFile

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        An unreadable file, or values that are not a camera; the message names the file and
        shows a valid example.
    """
    path = Path(path)
    if not path.is_file():
        inline = _inline_camera(str(path))
        if inline is not None:
            return CameraFile(inline, source=path)
        raise FileNotFoundError(f"intrinsics file {path} does not exist (the camera can also "
                                "be given inline as fx,fy,cx,cy, e.g. 525,525,319.5,239.5)")
    suffix = path.suffix.lower()
    try:
        text = path.read_text()
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not a text file; {_INTRINSICS_EXAMPLE}") from exc
    if suffix == ".txt":
        return CameraFile(_text_camera(path, text), source=path)
    if suffix == ".json":
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: not valid JSON ({exc.msg}, line {exc.lineno} column "
                             f"{exc.colno}); {_INTRINSICS_EXAMPLE}") from exc
    elif suffix in (".yaml", ".yml"):
        try:
            import yaml
        except ImportError as exc:
            raise ImportError("reading YAML needs PyYAML: pip install 'depthnormals[io]'") from exc
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ValueError(f"{path}: not valid YAML ({exc}); {_INTRINSICS_EXAMPLE}") from exc
    else:
        raise ValueError(f"{path}: intrinsics must be .json, .yaml/.yml or .txt (3x3 K, 3x4 P or "
                         "3F2N params.txt)")
    if not isinstance(data, dict):
        raise ValueError(f"{path}: needs keys fx, fy, cx, cy or K (3x3); {_INTRINSICS_EXAMPLE}")
    try:
        return _mapping_camera(data, path)
    except (ValueError, TypeError) as exc:
        raise type(exc)(f"{path}: {exc}; {_INTRINSICS_EXAMPLE}") from exc


def _text_camera(path: Path, text: str) -> Intrinsics:
    try:
        values = [float(x) for x in text.replace(",", " ").replace(";", " ").split()]
    except ValueError as exc:
        raise ValueError(f"{path}: expected numbers only: 9 (a 3x3 K), 12 (a 3x4 P) or 4-5 "
                         "(3F2N params.txt: fx fy cx cy [N])") from exc
    try:
        if len(values) == 9:
            return as_intrinsics(np.reshape(values, (3, 3)))
        if len(values) == 12:
            return as_intrinsics(np.reshape(values, (3, 4)))
        if len(values) in (4, 5):
            fx, fy, cx, cy = values[:4]
            return Intrinsics(fx, fy, cx - 1.0, cy - 1.0)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{path}: {exc}") from exc
    raise ValueError(f"{path} holds {len(values)} numbers; a text camera file holds 9 (a 3x3 K, "
                     "row-major), 12 (a 3x4 P) or 4-5 (3F2N params.txt: fx fy cx cy [N], 1-based)")


def _matrix(value: Any) -> np.ndarray:
    if isinstance(value, dict) and "data" in value:  # ROS camera_calibration_parsers
        value = value["data"]
    m = np.asarray(value, dtype=np.float64)
    if m.size == 9:
        return m.reshape(3, 3)
    if m.size == 12:
        return m.reshape(3, 4)
    raise ValueError(f"a camera matrix holds 9 (3x3) or 12 (3x4) numbers; got {m.size}")


def _mapping_camera(data: dict, path: Path) -> CameraFile:
    extras = dict(data)
    for key in ("camera", "intrinsics"):
        if isinstance(data.get(key), dict):
            data = data[key]
            extras.update({k: v for k, v in data.items() if k in _EXTRAS})
    if "intrinsic_matrix" in data:  # Open3D PinholeCameraIntrinsic: column-major
        m = np.asarray(data["intrinsic_matrix"], dtype=np.float64)
        if m.size != 9:
            raise ValueError(f"intrinsic_matrix holds {m.size} numbers; Open3D writes 9 (column-major)")
        K = as_intrinsics(m.reshape(3, 3).T)
    else:
        found = next((k for k in ("K", "k", "camera_matrix", "P", "p", "projection_matrix") if k in data),
                     None)
        if found is not None:
            K = as_intrinsics(_matrix(data[found]))
        elif all(k in data for k in ("fx", "fy", "cx", "cy")):
            K = as_intrinsics(data)
        else:
            raise ValueError("needs keys fx, fy, cx, cy or K (3x3) (or P (3x4), camera_matrix (ROS), "
                             "intrinsic_matrix (Open3D))")
    scale = extras.get("depth_scale")
    if scale is not None:
        scale = check_positive(scale, '"depth_scale"')
    invalid = extras.get("invalid", extras.get("invalid_value", ()))
    if isinstance(invalid, (int, float)) and not isinstance(invalid, bool):
        invalid = [invalid]
    if not isinstance(invalid, (list, tuple)):
        raise ValueError(f"invalid must be a list of raw depth values, e.g. [0, 65535]; got {invalid!r}")
    codes = tuple(_finite(c, '"invalid"') for c in invalid)
    max_depth = extras.get("max_depth")
    if max_depth is not None:
        max_depth = check_positive(max_depth, '"max_depth"')
    encoding = extras.get("encoding")
    if encoding is not None and not isinstance(encoding, str):
        raise ValueError(f'"encoding" must be a name such as "linear"; got {encoding!r}')
    raw_format = extras.get("raw_format")
    return CameraFile(K, scale, codes, max_depth, path, encoding,
                      None if raw_format is None else str(raw_format),
                      lens_distortion(extras.get("distortion"), '"distortion"'),
                      *_ros_lens(data))


def _ros_lens(data: dict) -> tuple[tuple[float, ...], str]:
    """A ROS ``camera_info``'s ``D`` when non-zero and of OpenCV's models, and ""; ``((),
    model)`` where a non-zero ``D`` is of another model or not OpenCV's coefficients; ``((),
    "")`` where there is none."""
    model = str(data.get("distortion_model", "plumb_bob")).strip() or "(none named)"
    value = next((data[k] for k in ("D", "d", "distortion_coefficients") if k in data), None)
    if isinstance(value, dict):
        value = value.get("data", ())
    try:
        d = np.asarray(value if value is not None else (), dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        return (), model
    if not np.any(d != 0):  # none, or all 0 (most depth cameras' camera_info)
        return (), ""
    if model.lower() not in OPENCV_MODELS:
        return (), model
    try:
        return lens_distortion(d), ""
    except (TypeError, ValueError):
        return (), model


_EXTRAS = ("depth_scale", "invalid", "invalid_value", "max_depth", "encoding", "raw_format",
           "distortion")


def _inline_camera(text: str) -> Intrinsics | None:
    """``fx,fy,cx,cy`` written out (four comma-separated numbers), or None if ``text`` is not
    that; the numbers are checked as any camera's (ValueError)."""
    parts = text.split(",")
    if len(parts) != 4:
        return None
    try:
        fx, fy, cx, cy = (float(p) for p in parts)
    except ValueError:
        return None
    return as_intrinsics((fx, fy, cx, cy))


def read_intrinsics(path: str | Path) -> Intrinsics:
    """Read camera intrinsics from any file :func:`read_camera_file` reads (its ``K``)."""
    return read_camera_file(path).K


_INTRINSICS_EXAMPLE = ('a valid file looks like {"fx": 525.0, "fy": 525.0, "cx": 319.5, '
                       '"cy": 239.5} (pixels, 0-based principal point) or {"K": [[525.0, 0, '
                       '319.5], [0, 525.0, 239.5], [0, 0, 1]]}, optionally with "depth_scale", '
                       '"invalid" and "max_depth"')


def normals_to_rgb8(normals: np.ndarray, *, convention: str = "3f2n") -> np.ndarray:
    """8-bit colour picture of a normal map, black where invalid.

    Parameters
    ----------
    normals : array (H, W, 3)
    convention : {"3f2n", "open3d"}
        ``"3f2n"`` (default): ``RGB = (1 - n) / 2 * 255``, the 3F2N papers' colouring (a
        camera-facing wall, n = (0, 0, -1), is light blue (128, 128, 255)). ``"open3d"``:
        ``RGB = (n + 1) / 2 * 255``, the usual colouring of Open3D and most viewers (the same
        wall is (128, 128, 0)).
    """
    if convention not in VIS_CONVENTIONS:
        raise ValueError(f"unknown colour convention {convention!r}; use one of {', '.join(VIS_CONVENTIONS)}")
    n = check_normals(normals)
    ok = np.all(np.isfinite(n), axis=-1)
    m = np.nan_to_num(n)
    m = (1.0 - m) if convention == "3f2n" else (m + 1.0)
    rgb = np.clip(m * 0.5 * 255.0 + 0.5, 0, 255).astype(np.uint8)
    rgb[~ok] = 0
    return rgb


#: Output suffixes of a normal map (:func:`write_normals`) and of a point cloud (:func:`write_ply`).
OUTPUT_SUFFIXES = (".npy", ".png", ".vis.png", ".ply")


def write_normals(path: str | Path, normals: np.ndarray, *, vis: str = "3f2n") -> None:
    """Write a normal map: ``.npy`` (float32), ``.png`` (16-bit, see module doc); atomic.

    A name ending in ``.vis.png`` writes the 8-bit picture of :func:`normals_to_rgb8` instead
    (colouring ``vis``: ``"3f2n"`` or ``"open3d"``).
    """
    path = Path(path)
    n = check_normals(normals)
    name = path.name.lower()
    if name.endswith(".npy"):
        with atomic_write(path) as fh:
            np.save(fh, n.astype(np.float32))
    elif name.endswith(".vis.png"):
        write_png(path, normals_to_rgb8(n, convention=vis))
    elif name.endswith(".png"):
        ok = np.all(np.isfinite(n), axis=-1)
        enc = np.clip(np.round((np.nan_to_num(n) + 1.0) * 0.5 * 65535.0), 0, 65535).astype(np.uint16)
        enc[~ok] = 0
        write_png(path, enc)
    else:
        raise ValueError(f"{path}: normals are written as .npy, .png (16-bit) or .vis.png (8-bit "
                         "picture); a point cloud as .ply (write_ply)")


def read_normals(path: str | Path) -> np.ndarray:
    """Read normals written by :func:`write_normals` (.npy or 16-bit .png) as float32."""
    path = Path(path)
    if path.suffix.lower() == ".npy":
        return check_normals(np.load(path, allow_pickle=False)).astype(np.float32)
    img = read_png(path)
    if img.dtype != np.uint16 or img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"{path}: expected a 16-bit RGB normal PNG; got {img.dtype} {img.shape}")
    n = img.astype(np.float64) / 65535.0 * 2.0 - 1.0
    bad = np.all(img == 0, axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    n[bad] = np.nan
    return n.astype(np.float32)


# --- point clouds -------------------------------------------------------------------------

_PLY_FIELDS = (("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4"))
_PLY_COLOURS = (("red", "u1"), ("green", "u1"), ("blue", "u1"))
_PLY_UNCERTAINTY = (("uncertainty", "<f4"),)


def _cloud(depth: Any, K: Any, normals: Any, colors: Any, uncertainty: Any = None
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Points (float64), normals, colours and uncertainty of the valid pixels (finite depth > 0
    and finite normal; the uncertainty does not choose them)."""
    from .camera import backproject

    z = check_depth(depth)
    n = check_normals(normals, shape=z.shape)
    points = backproject(z, K)
    valid = np.all(np.isfinite(points), axis=-1) & np.all(np.isfinite(n), axis=-1)
    rgb = None
    if colors is not None:
        rgb = np.asarray(colors)
        if rgb.dtype != np.uint8:
            raise TypeError(f"colors must be uint8 (H, W, 3); got dtype {rgb.dtype}")
        if rgb.shape != (*z.shape, 3):
            raise ValueError(f"colors must have shape {(*z.shape, 3)} like depth; got {rgb.shape}")
        rgb = rgb[valid]
    unc = None
    if uncertainty is not None:
        unc = np.asarray(uncertainty)
        if unc.dtype == bool or unc.dtype.kind not in "iuf":
            raise TypeError(f"uncertainty must be a real (H, W) array (degrees, from "
                            f"estimate_normals(..., return_uncertainty=True)); got dtype {unc.dtype}")
        if unc.shape != z.shape:
            raise ValueError(f"uncertainty must have shape {z.shape} like depth; got {unc.shape}")
        unc = unc[valid]
    return points[valid], np.asarray(n[valid]), rgb, unc


def write_ply(path: str | Path, depth: Any, K: Any, normals: Any, *, colors: Any = None,
              uncertainty: Any = None) -> int:
    """Write the valid pixels as a binary little-endian PLY point cloud, atomically.

    Parameters
    ----------
    path : str or Path
        Output ``.ply`` file; replaced atomically (a crash leaves the old file or none).
    depth : array (H, W), float32 or float64
        Planar depth in metres (integer depth: scale it first); invalid pixels are skipped.
    K : Intrinsics, array (3, 3) or (fx, fy, cx, cy)
        Camera intrinsics, 0-based pixel centres.
    normals : array (H, W, 3)
        Normals in the OpenCV camera frame (e.g. from :func:`depthnormals.estimate_normals`);
        pixels with a NaN normal are skipped.
    colors : array (H, W, 3) uint8, optional
        Per-pixel RGB, written as ``uchar red green blue``.
    uncertainty : array (H, W), optional
        The expected angular error of each normal in degrees
        (``estimate_normals(..., return_uncertainty=True)``), written as ``float uncertainty``.
        It does not choose the points: a point is written where depth and normal are valid,
        with its value as given (the library's map is NaN exactly where the normal is NaN, so
        every written value is finite).

    Returns
    -------
    int
        The number of points written.

    Notes
    -----
    One ``vertex`` element with ``float x y z nx ny nz`` (float32: the points of
    :func:`depthnormals.backproject` rounded to float32, the normals as given rounded to
    float32), then ``uchar red green blue`` when ``colors`` is given, then
    ``float uncertainty`` when ``uncertainty`` is given, in row-major pixel order.
    Camera frame: OpenCV (x right, y down, z forward), metres. Open3D, plyfile and MeshLab read it.

    Examples
    --------
    >>> import tempfile, os
    >>> import numpy as np
    >>> depth = np.full((4, 5), 2.0)
    >>> n = np.zeros((4, 5, 3), np.float32); n[..., 2] = -1
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     write_ply(os.path.join(tmp, "wall.ply"), depth, (100, 100, 2, 1.5), n)
    20
    """
    points, n, rgb, unc = _cloud(depth, K, normals, colors, uncertainty)
    fields = (_PLY_FIELDS + (_PLY_COLOURS if rgb is not None else ())
              + (_PLY_UNCERTAINTY if unc is not None else ()))
    records = np.empty(len(points), dtype=list(fields))
    for i, axis in enumerate("xyz"):
        records[axis] = points[:, i]
        records["n" + axis] = n[:, i]
    if rgb is not None:
        for i, name in enumerate(("red", "green", "blue")):
            records[name] = rgb[:, i]
    if unc is not None:
        records["uncertainty"] = unc
    types = {"<f4": "float", "u1": "uchar"}
    header = "".join([
        "ply\n", "format binary_little_endian 1.0\n",
        "comment depthnormals point cloud, OpenCV camera frame\n",
        f"element vertex {len(records)}\n",
        *(f"property {types[t]} {name}\n" for name, t in fields),
        "end_header\n",
    ]).encode("ascii")
    with atomic_write(path) as fh:
        fh.write(header)
        fh.write(records.tobytes())
    return len(records)


def to_open3d(depth: Any, K: Any, normals: Any, *, colors: Any = None) -> Any:
    """The valid pixels as an ``open3d.geometry.PointCloud`` with normals (and colours).

    Parameters
    ----------
    depth, K, normals, colors
        As in :func:`write_ply`.

    Returns
    -------
    open3d.geometry.PointCloud
        ``points`` from :func:`depthnormals.backproject` (float64), ``normals`` as given,
        ``colors`` scaled to [0, 1]; OpenCV camera frame, row-major pixel order. Needs the
        ``open3d`` extra (``pip install 'depthnormals[open3d]'``, which installs ``open3d-cpu``).

    Notes
    -----
    Open3D 0.20 bundles TBB 2021.5. Once it is loaded, numba's first parallel kernel warns
    (``NumbaWarning``) that this TBB is too old and picks another threading layer; results
    are unaffected. Our tests therefore use Open3D in a subprocess.
    """
    try:
        import open3d as o3d
    except ImportError as exc:
        raise ImportError("to_open3d needs Open3D: pip install 'depthnormals[open3d]' "
                          "(or the open3d / open3d-cpu wheel)") from exc
    points, n, rgb, _ = _cloud(depth, K, normals, colors)
    cloud = o3d.geometry.PointCloud()
    cloud.points = o3d.utility.Vector3dVector(np.ascontiguousarray(points, dtype=np.float64))
    cloud.normals = o3d.utility.Vector3dVector(np.ascontiguousarray(n, dtype=np.float64))
    if rgb is not None:
        cloud.colors = o3d.utility.Vector3dVector(rgb.astype(np.float64) / 255.0)
    return cloud
