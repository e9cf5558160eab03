"""The first-run announcement: is numba's on-disk cache of the package's kernels cold?

The compiled kernels are numba functions with ``cache=True``. numba keeps, per source file, one
index file ``<module>.<function>-<line>.py<XY>.nbi`` per kernel in the file's cache folder:
``$NUMBA_CACHE_DIR/<folder>_<sha1 of the folder path>/`` when ``NUMBA_CACHE_DIR`` is set,
else ``__pycache__`` beside the source (or numba's user-wide cache folder when that is not
writable). An index is fresh when it was written by this numba version for the current source
(numba stamps it with a hash of the file, or (mtime, size) in older versions; for the package's
own kernels :mod:`depthnormals._numba_cache` pairs that stamp with the digest of the package's
compiled code, and only that pair is fresh).

:func:`kernel_cache_state` reads only those index files (a few ms): ``"warm"`` when some kernel
module has a fresh index, else ``"stale"`` when indexes exist but none is fresh (the package
changed since it was compiled: an upgrade, an edit) or ``"cold"`` when there are none (a new
install, an empty cache). The package as a whole counts, not each module: numba never deletes
old index files, so a module no command uses would otherwise look stale forever. The price: a
warm cache can still compile a method used for the first time; the announcement is a hint
for the first run, not a promise about every run.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import sys
from pathlib import Path

__all__ = ["announce_first_run", "kernel_cache_state"]

#: A source file holds compiled kernels when it contains this text.
_KERNEL_MARK = b"cache=True"
_announced = False


def _kernel_modules(package_dir: Path) -> list[Path]:
    return sorted(p for p in package_dir.rglob("*.py")
                  if "__pycache__" not in p.parts and _KERNEL_MARK in p.read_bytes())


def _cache_dirs(py_file: Path) -> list[Path]:
    """Where numba keeps the cache of ``py_file`` (its locators, in numba's order)."""
    import numba

    folder = py_file.resolve().parent
    sub = f"{folder.name}_{hashlib.sha1(str(folder).encode()).hexdigest()}"
    if numba.config.CACHE_DIR:
        return [Path(numba.config.CACHE_DIR) / sub]
    dirs = [folder / "__pycache__"]
    try:
        from numba.misc.appdirs import AppDirs

        dirs.append(Path(AppDirs(appname="numba", appauthor=False).user_cache_dir) / sub)
    except ImportError:  # pragma: no cover - numba's layout changed; in-tree only
        pass
    return dirs


def _index_is_fresh(index: Path, source: bytes, stat: os.stat_result, version: str,
                    package: str | None = None) -> bool:
    """Whether numba would load the index: its version, and its source stamp numba's own
    (a hash of the file, or (mtime, size)) or, for a folder whose stamp
    :mod:`depthnormals._numba_cache` extends, that pair with the folder's compiled-code
    digest ``package``."""
    try:
        with open(index, "rb") as fh:
            if pickle.load(fh) != version:
                return False
            stamp = pickle.loads(fh.read())[0]
    except Exception:  # unreadable or from another numba: numba recompiles, so not fresh
        return False
    own = (hashlib.sha256(source).digest(), (stat.st_mtime, stat.st_size))
    if package is not None:
        return isinstance(stamp, tuple) and len(stamp) == 2 and stamp[0] in own \
            and stamp[1] == package
    return stamp in own


def _package_digest(root: Path) -> str | None:
    """The compiled-code digest :mod:`depthnormals._numba_cache` adds to the stamps of the
    kernels under ``root`` (None where it adds none: a folder it does not know)."""
    from .. import _numba_cache

    deps = _numba_cache._ROOTS.get(root.resolve())
    return None if deps is None else _numba_cache.compiled_code_digest(root.resolve(), deps)


def kernel_cache_state(package_dir: str | Path | None = None) -> str:
    """``"cold"``, ``"stale"`` or ``"warm"``: numba's cache of the kernels in ``package_dir``.

    Parameters
    ----------
    package_dir : str or Path, optional
        Folder whose ``*.py`` files are searched for ``cache=True`` kernels; default the
        installed ``depthnormals`` package.

    Returns
    -------
    str
        ``"warm"``: some kernel module has a fresh cache index; ``"stale"``: index files
        exist but none is fresh (the sources changed since); ``"cold"``: no index at all.
    """
    import numba

    root = Path(package_dir) if package_dir is not None else Path(__file__).resolve().parents[1]
    package = _package_digest(root)
    any_fresh = stale = False
    for module in _kernel_modules(root):
        indexes = [p for d in _cache_dirs(module) if d.is_dir()
                   for p in d.glob(f"{module.stem}.*.nbi")]
        if not indexes:
            continue
        source, stat = module.read_bytes(), module.stat()
        if any(_index_is_fresh(p, source, stat, numba.__version__, package) for p in indexes):
            any_fresh = True
        else:
            stale = True
    if any_fresh:
        return "warm"
    return "stale" if stale else "cold"


def announce_first_run(command: str, seconds: float | None) -> bool:
    """Print "compiling kernels, first run only (about N s)" on stderr once per process, when
    the command compiles kernels (``seconds`` not None) and the cache is cold or stale.

    Returns whether it printed.
    """
    global _announced
    if _announced or seconds is None:
        return False
    import numba

    if numba.config.DISABLE_JIT or kernel_cache_state() == "warm":
        return False
    _announced = True
    print(f"depthnormals {command}: compiling kernels, first run only (about {seconds:.0f} s)",
          file=sys.stderr, flush=True)
    return True
