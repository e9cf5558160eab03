"""Digests that tell a stored result from a stale one: of the library's own code and of arrays.

A resumed run may reuse what an earlier run stored only if nothing that determines it has
changed since: the data it was computed from and the code that computed it. The library's
version string alone does not tell (it stays the same between development builds), so
:func:`code_fingerprint` hashes the package's modules themselves.
"""

from __future__ import annotations

import hashlib
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["PACKAGE_ROOT", "array_digest", "code_fingerprint"]


#: The folder of the installed ``depthnormals`` package.
PACKAGE_ROOT = Path(__file__).resolve().parent


@lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """A hex digest of every Python module of the installed ``depthnormals`` package (its
    path inside the package and its bytes): any edit of the code changes it. Computed once per
    process (a few ms)."""
    h = hashlib.blake2b(digest_size=12)
    for path in sorted(PACKAGE_ROOT.rglob("*.py")):
        h.update(path.relative_to(PACKAGE_ROOT).as_posix().encode())
        h.update(b"\0")
        try:
            h.update(path.read_bytes())
        except OSError:  # unreadable (a broken link): counted by name
            h.update(b"unreadable")
        h.update(b"\0")
    return h.hexdigest()


def array_digest(*arrays: Any) -> str:
    """A hex digest of the arrays' dtypes, shapes and bytes (None counts as an absent array):
    equal exactly when every array is, bit for bit."""
    h = hashlib.blake2b(digest_size=12)
    for a in arrays:
        if a is None:
            h.update(b"none;")
            continue
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape};".encode())
        if a.dtype.hasobject:  # objects (a camera given as Intrinsics): their repr
            h.update(repr(a.tolist()).encode())
        elif a.size:
            h.update(a.view(np.uint8).reshape(-1).data)
    return h.hexdigest()
