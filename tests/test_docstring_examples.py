"""Every docstring example of the package runs as written (``doctest``), module by module.

The modules are found on disk (no import at collection: ``import depthnormals`` must not pull
in torch or matplotlib, and walking the package would); a module whose source holds an
example (``>>>``) must yield examples to doctest, so a docstring doctest cannot read is a
failure, not a silent skip. Examples that write files write into the test's temporary folder.
"""

from __future__ import annotations

import doctest
import importlib
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "depthnormals"


def _modules_with_examples() -> list[str]:
    names = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "__main__.py" or ">>> " not in path.read_text(encoding="utf-8"):
            continue
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return names


MODULES = _modules_with_examples()


def test_the_package_has_examples_to_run():
    """The scan finds the modules with examples (about 40 of them); an empty scan (a moved
    source tree) would make every test below vacuous."""
    assert len(MODULES) >= 30
    assert "depthnormals.registry" in MODULES and "depthnormals.ddm.uncertainty" in MODULES


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name, tmp_path, monkeypatch):
    if name.startswith("depthnormals.torch"):
        pytest.importorskip("torch")
    module = importlib.import_module(name)
    monkeypatch.chdir(tmp_path)
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE | doctest.ELLIPSIS,
                             report=True)
    assert result.attempted > 0, f"{name} holds '>>> ' but doctest found no example in it"
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples of {name} failed"
