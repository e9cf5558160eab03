"""numba's cache of a compiled function goes stale when any module of its package changes
(``depthnormals._numba_cache``), not only its own file: a caller compiled with an old callee
from another file is never loaded again."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from depthnormals._fingerprint import PACKAGE_ROOT

CALLER = """
import numba as nb
from .b import g

@nb.njit(cache=True)
def f(x):
    return g(x) * 10
"""
CALLEE = """
import numba as nb

@nb.njit(cache=True)
def g(x):
    return x + {step}
"""


def _run(folder, env):
    code = "from pk.a import f; print(f(1), sum(f.stats.cache_hits.values()))"
    out = subprocess.run([sys.executable, "-c", code], cwd=folder, env=env, capture_output=True,
                         text=True, check=True, timeout=120)
    value, hits = out.stdout.split()
    return int(value), int(hits)


@pytest.mark.parametrize("user_cache_dir", [False, True], ids=["in-tree", "NUMBA_CACHE_DIR"])
def test_an_edited_callee_in_another_file_recompiles_its_caller(tmp_path, user_cache_dir):
    """numba 0.68 alone: the caller's cache loads after the callee's file changed and returns
    20 where 30 is right (measured). With the locator: a miss, 30, then a hit again."""
    pk = tmp_path / "pk"
    pk.mkdir()
    (pk / "__init__.py").write_text(textwrap.dedent("""
        from pathlib import Path
        from depthnormals._numba_cache import install
        assert install(Path(__file__).parent)
    """))
    (pk / "a.py").write_text(CALLER)
    (pk / "b.py").write_text(CALLEE.format(step=1))
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    env.pop("NUMBA_CACHE_DIR", None)
    if user_cache_dir:
        env["NUMBA_CACHE_DIR"] = str(tmp_path / "cache")
    assert _run(tmp_path, env) == (20, 0)
    assert _run(tmp_path, env) == (20, 1)        # cached
    (pk / "b.py").write_text(CALLEE.format(step=2))
    assert _run(tmp_path, env) == (30, 0)        # the callee changed: compiled again
    assert _run(tmp_path, env) == (30, 1)
    if user_cache_dir:
        assert any((tmp_path / "cache").rglob("*.nbi"))
        assert not (pk / "__pycache__").exists() or not any((pk / "__pycache__").glob("*.nbi"))


def test_every_cached_kernel_of_the_package_is_stamped_with_the_package_digest():
    import numba

    import depthnormals  # noqa: F401  (installs the locator first)
    from depthnormals._numba_cache import DEPENDENCIES, compiled_code_digest
    from depthnormals.ddm import boxfit, support
    from depthnormals.kernels import stencils, threefn_rows

    found = 0
    for module in (threefn_rows, stencils, boxfit, support):
        for name, obj in vars(module).items():
            cache = getattr(obj, "_cache", None)
            if not isinstance(obj, numba.core.registry.CPUDispatcher) or not hasattr(cache, "_impl"):
                continue
            locator = cache._impl.locator
            assert type(locator).__name__ == "PackageStampLocator", (module.__name__, name)
            assert locator.get_source_stamp()[1] == compiled_code_digest(PACKAGE_ROOT, DEPENDENCIES)
            found += 1
    assert found >= 10


def _module_names() -> dict[str, Path]:
    """Every module of the package by dotted name."""
    names = {}
    for path in PACKAGE_ROOT.rglob("*.py"):
        rel = path.relative_to(PACKAGE_ROOT.parent).with_suffix("")
        names[".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)] = path
    return names


def _package_imports(name: str, path: Path, names: dict[str, Path]) -> set[str]:
    """The package's modules that ``name`` imports anywhere in its file (lazy imports too)."""
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = package.split(".")[:len(package.split(".")) - node.level + 1] if node.level else []
            mod = ".".join(base + ([node.module] if node.module else []))
            subs = {f"{mod}.{a.name}" for a in node.names} & set(names)
            found |= subs
            if len(subs) < len(node.names):
                found.add(mod)
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
    return found & set(names)


def test_the_digest_covers_every_module_compiled_code_can_read():
    """Every module the compiling modules import (their constants and helpers can be frozen
    into the machine code) is in the digest: it mentions ``jit`` or is listed in
    ``DEPENDENCIES``. A new import of a pure module by a compiling one fails here until listed."""
    from depthnormals._numba_cache import DEPENDENCIES

    names = _module_names()
    root = PACKAGE_ROOT
    text = {n: p.read_bytes() for n, p in names.items()}
    covered = {n for n in names if b"jit" in text[n]
               or names[n].relative_to(root).as_posix() in DEPENDENCIES}
    compiling = {n for n in names if b"@nb.njit" in text[n] or b"@numba.njit" in text[n]}
    assert len(compiling) >= 25
    closure, todo = set(compiling), list(compiling)
    while todo:
        n = todo.pop()
        for m in _package_imports(n, names[n], names) - closure:
            closure.add(m)
            todo.append(m)
    assert closure - covered == set()
    listed = {f"depthnormals.{d[:-3].replace('/', '.')}" for d in DEPENDENCIES}
    assert listed <= closure, "DEPENDENCIES lists a module no compiled code imports"


def test_a_front_end_edit_keeps_the_kernels_cached(tmp_path):
    """The command line, readers, torch and the evaluation's Python are not in the digest: an
    edit there recompiles nothing; an edit of a listed dependency does."""
    import shutil

    from depthnormals._numba_cache import DEPENDENCIES, compiled_code_digest

    pkg = tmp_path / "depthnormals"
    shutil.copytree(PACKAGE_ROOT, pkg, ignore=shutil.ignore_patterns("__pycache__"))

    def digest():
        return compiled_code_digest.__wrapped__(pkg, DEPENDENCIES)

    def edit(rel):
        (pkg / rel).write_text((pkg / rel).read_text() + "\n# an edit\n")

    before = digest()
    for rel in ("cli.py", "datasets/nyu.py", "torch/_api.py", "evaluate/_run.py", "jobs.py"):
        edit(rel)
    assert digest() == before
    for rel in ("kernels/depth.py", "kernels/stencils.py", "ddm/uncertainty.py"):
        edit(rel)
        assert digest() != before
        before = digest()


def test_an_unreadable_module_does_not_stop_the_import(tmp_path):
    """The digest is taken when the first kernel is defined, i.e. at ``import depthnormals``:
    a module it cannot read (a broken link left by an interrupted upgrade) is counted by name,
    not raised."""
    from depthnormals._numba_cache import compiled_code_digest

    (tmp_path / "a.py").write_text("import numba\n@numba.njit(cache=True)\ndef f(): return 1\n")
    (tmp_path / "gone.py").symlink_to(tmp_path / "missing.py")
    first = compiled_code_digest.__wrapped__(tmp_path)
    (tmp_path / "gone.py").unlink()
    assert compiled_code_digest.__wrapped__(tmp_path) != first


_BOX_SCORES = """
import sys
import numpy as np
from depthnormals.analytic import make_scene
from depthnormals.ddm.boxfit import box_fit_windows
from depthnormals.synth.noise import kinect_v2_noise
r = make_scene("box-on-floor").render(shape=(240, 320), K=(290.0, 290.0, 159.5, 119.5))
d = kinect_v2_noise(r.depth, r.normals, r.K, rng=np.random.default_rng(0))
z = np.where(np.isfinite(d) & (d > 0), d, np.nan).astype(np.float32)
_, s = box_fit_windows(z, 290.0, 290.0, 159.5, 119.5, 2, normals=False)
np.save(sys.argv[1], s)
"""


def test_a_compiling_run_and_a_cached_run_give_the_same_bits(tmp_path):
    """The box fit's residual scores (what the default's window choice and map read) from a
    process that compiles the kernels and from one that loads them from numba's cache: equal
    to the bit. With the ``reassoc`` fast-math flag (until session 39) they were not (here 5
    of 76,800 pixels; a kinect_v2 preset frame 80 of 217,088): LLVM reassociated the sums of
    the freshly compiled code otherwise than those of the cached one."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    runs = []
    for name in ("cold", "warm"):
        out = tmp_path / f"{name}.npy"
        subprocess.run([sys.executable, "-c", _BOX_SCORES, str(out)], env=env, check=True,
                       timeout=300, capture_output=True)
        runs.append(np.load(out))
    assert np.isfinite(runs[0]).mean() > 0.3  # the floor and the box (the rest sees nothing)
    np.testing.assert_array_equal(runs[0], runs[1])
