"""numba's on-disk cache, stale when any code a compiled function can hold changes, not only its file.

``@njit(cache=True)`` keys a compiled function's cache on the bytes of the file that defines
it. A compiled function holds the machine code of the compiled functions it calls, so when a
callee in another file changes (a shared kernel of :mod:`depthnormals.kernels`) the caller's
cache still loads, and returns the old callee's results. It happens wherever the cache files
outlive the code: a ``git pull`` into an editable install, and ``pip install --upgrade``, which
leaves numba's ``__pycache__/*.nbi``/``*.nbc`` files behind (they are not in the wheel's
RECORD), so a module unchanged between two versions loads its old machine code. Measured
with numba 0.68.1: a cached caller of an edited callee in another file kept the old result.

:func:`install` puts a locator first in numba's list that, for the files under a registered
folder (``depthnormals``'s own, at import), adds to numba's source stamp the digest of every
module there that the machine code can hold (:func:`compiled_code_digest`: the modules that
compile, and :data:`DEPENDENCIES`, those whose names they read); it finds the cache folder as
numba would (``NUMBA_CACHE_DIR`` honoured). An edit of any of them recompiles every cached
function once; an edit of a front end (the command line, the readers, torch, the
evaluation's Python) recompiles nothing. It uses numba's private ``numba.core.caching``
classes; where they are missing (another numba) nothing is installed and numba's own rule
stays. ``NUMBA_CACHE_LOCATOR_CLASSES``, if set, replaces numba's list, this locator included.
"""

from __future__ import annotations

import hashlib
from functools import lru_cache
from pathlib import Path
from typing import Any

from ._fingerprint import PACKAGE_ROOT

__all__ = ["DEPENDENCIES", "compiled_code_digest", "install"]

#: The package's modules without compiled code whose names compiled code reads (constants,
#: helpers), as paths inside the package: their edits reach the machine code too.
#: ``tests/test_numba_cache.py`` checks this against the imports of every module that compiles.
DEPENDENCIES = ("_parallel.py", "_validate.py", "camera.py", "ddm/_module.py", "io.py",
                "kernels/depth.py")

_ROOTS: dict[Path, tuple[str, ...]] = {}


@lru_cache(maxsize=8)
def compiled_code_digest(root: Path, dependencies: tuple[str, ...] = ()) -> str:
    """A hex digest of the modules under ``root`` that the machine code can hold: those that
    mention ``jit`` (every module defining compiled functions; a few more do no harm) and
    ``dependencies`` (paths inside ``root``). Once per process and folder (a few ms)."""
    root = Path(root)
    extra = set(dependencies)
    h = hashlib.blake2b(digest_size=12)
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        try:
            data = path.read_bytes()
        except OSError:  # unreadable (a broken link): counted by name, never an import error
            data = b"jit: unreadable"
        if b"jit" in data or rel in extra:
            h.update(rel.encode() + b"\0" + data + b"\0")
    return h.hexdigest()


def _root_of(py_file: str) -> Path | None:
    try:
        path = Path(py_file).resolve()
    except (OSError, RuntimeError):
        return None
    for root in _ROOTS:
        if path.is_relative_to(root):
            return root
    return None


def _impl_class(caching: Any) -> Any:
    """numba's cache implementation class (``CacheImpl`` in numba 0.68, ``_CacheImpl`` in
    some older releases)."""
    impl = getattr(caching, "CacheImpl", None)
    return impl if impl is not None else caching._CacheImpl


def _locator_class() -> Any:
    from numba.core import caching

    class PackageStampLocator(caching._CacheLocator):
        """numba's own locator for the function, with the digest of its package's compiled
        code added to the source stamp."""

        def __init__(self, inner: Any, root: Path) -> None:
            self._inner = inner
            self._root = root

        def ensure_cache_path(self) -> None:
            self._inner.ensure_cache_path()

        def get_cache_path(self) -> str:
            return self._inner.get_cache_path()

        def get_source_stamp(self) -> Any:
            return (self._inner.get_source_stamp(), compiled_code_digest(self._root, _ROOTS[self._root]))

        def get_disambiguator(self) -> str:
            return self._inner.get_disambiguator()

        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> Any:
            root = _root_of(py_file)
            if root is None:
                return None
            for other in _impl_class(caching)._locator_classes:
                if other is cls:
                    continue
                inner = other.from_function(py_func, py_file)
                if inner is not None:
                    return cls(inner, root)
            return None

    return PackageStampLocator


def install(root: str | Path = PACKAGE_ROOT, dependencies: tuple[str, ...] | None = None) -> bool:
    """Make the numba caches of the functions under ``root`` stale whenever a module under it
    that compiled code can hold changes (the module docstring): the modules that mention
    ``jit`` and ``dependencies`` (paths inside ``root``; :data:`DEPENDENCIES` for the package's
    own root, none for another). Idempotent; True when the locator is in place."""
    try:
        from numba.core import caching

        classes = _impl_class(caching)._locator_classes
        ours = next((c for c in classes if c.__name__ == "PackageStampLocator"), None)
        if ours is None:
            ours = _locator_class()
            classes.insert(0, ours)
    except (ImportError, AttributeError, TypeError):  # another numba: its own rule stays
        return False
    root = Path(root).resolve()
    if dependencies is None:
        dependencies = DEPENDENCIES if root == PACKAGE_ROOT else ()
    _ROOTS[root] = tuple(dependencies)
    return True


install()
