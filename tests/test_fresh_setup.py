"""The README's set-up is what CI runs, on a fresh machine (issue: "a fresh machine passes
the README"). These read the files; the fresh virtual environment itself is `.ci/run`'s job."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _readme_test_command() -> str:
    text = (ROOT / "README.md").read_text()
    m = re.search(r"<!-- test-command -->\n```bash\n(.+?)\n```", text)
    assert m, "README.md needs its test command in a ```bash block after <!-- test-command -->"
    return m.group(1)


def test_readme_test_command_installs_from_a_file_that_pins_the_cpu_torch():
    cmd = _readme_test_command()
    assert cmd == "pip install -r requirements-test.txt && python -m pytest -q"
    reqs = [line.strip() for line in (ROOT / "requirements-test.txt").read_text().splitlines()
            if line.strip() and not line.startswith("#")]
    assert "torch==2.13.0" in reqs               # the CPU wheel of the machine image, not CUDA
    assert "-e .[test,peers]" in reqs
    assert not any("index-url" in r or "find-links" in r for r in reqs)  # the default index only


def test_ci_runs_the_readme_command_in_a_new_venv_and_fails_on_no_tests():
    ci = (ROOT / ".ci" / "run").read_text()
    assert "python3 -m venv" in ci and "mktemp -d" in ci
    assert "<!-- test-command -->" in ci         # the command is read from the README, not copied
    assert '"$rc" = 5' in ci                     # pytest's "no tests collected" fails the run
    assert "apt-get install" in ci and "libusb-1.0-0" in ci
    program = re.search(r"awk '([^']+)' README.md", ci).group(1)
    extracted = subprocess.run(["awk", program, str(ROOT / "README.md")], capture_output=True, text=True,
                               check=True).stdout.strip()
    assert extracted == _readme_test_command()


def test_third_party_plugins_cannot_break_the_suite_but_our_warnings_stay_errors():
    text = (ROOT / "pyproject.toml").read_text()
    addopts = re.search(r'^addopts = "(.*)"$', text, re.M).group(1)
    assert "-p no:dash" in addopts
    assert re.search(r'filterwarnings = \[\s*"error",', text)


def test_pytest_starts_with_the_installed_plugins(tmp_path):
    """With dash 4.4 installed (open3d-cpu pulls it in), pytest 9 used to stop at plugin load
    (exit 3, no test run). A throw-away test file is collected and run here."""
    (tmp_path / "test_one.py").write_text("def test_ok():\n    pass\n")
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "-c", str(ROOT / "pyproject.toml"),
                          "--rootdir", str(tmp_path), "-p", "no:cacheprovider", str(tmp_path)],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "1 passed" in res.stdout


def test_readme_says_where_the_shared_data_is_and_what_is_skipped():
    text = (ROOT / "README.md").read_text()
    assert "../shared/data" in text and "tests/conftest.py" in text
    assert "skipped" in text and "no test is skipped" not in text
    conftest = (ROOT / "tests" / "conftest.py").read_text()
    assert 'parents[2] / "shared" / "data"' in conftest
