"""The package as a user installs it: a wheel built from pyproject.toml, installed (not editable)
into a fresh virtual environment, writes a report.

The wheel is built without isolation from a copy of the tracked sources (so nothing is written
into the checkout); the fresh environment reuses this environment's pinned dependencies through
a path file (a `.pth` line adds a directory to sys.path without running the `.pth` files in it,
so the editable install of this checkout stays invisible), and the wheel is installed into it
with uv, offline. The run is one stability cell; the report is rendered from it with
`harness report --from latest`, the same code path a full report takes after measuring.
"""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import tarfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _run(cmd, **kw):
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, **kw)
    assert proc.returncode == 0, (cmd, proc.stdout[-2000:], proc.stderr[-2000:])
    return proc


@pytest.mark.slow
def test_a_wheel_installed_in_a_fresh_environment_writes_a_report(tmp_path):
    tracked = _run(["git", "ls-files", "pyproject.toml", "README.md", "harness", "problems",
                    "implementations"], cwd=ROOT).stdout.split()
    src = tmp_path / "src"
    with tarfile.open(tmp_path / "src.tar", "w") as tar:
        for name in tracked:
            tar.add(ROOT / name, arcname=name)
    with tarfile.open(tmp_path / "src.tar") as tar:
        tar.extractall(src, filter="data")
    _run([sys.executable, "-m", "build", "--wheel", "--no-isolation", "-o", str(tmp_path / "dist"),
          str(src)])
    wheel = next((tmp_path / "dist").glob("*.whl"))

    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)])
    python = venv / "bin" / "python"
    site = _run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]
                ).stdout.strip()
    Path(site, "project-deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    _run([sys.executable, "-m", "uv", "pip", "install", "--offline", "--no-deps", "--quiet",
          "--python", str(python), str(wheel)])

    work = tmp_path / "work"
    work.mkdir()
    env = dict(os.environ, HARNESS_CACHE_DIR=str(tmp_path / "cache"),
               HARNESS_RESULTS_DIR=str(tmp_path / "results"),
               HARNESS_REPORTS_DIR=str(tmp_path / "reports"))
    env.pop("PYTHONPATH", None)
    where = _run([str(python), "-c", "import harness; print(harness.__file__)"], cwd=work, env=env)
    assert where.stdout.strip().startswith(site)  # the wheel's copy, not this checkout
    harness = str(venv / "bin" / "harness")
    _run([harness, "run", "stability", "--stepper", "euler", "--problem", "dahlquist", "--jobs",
          "1", "--quick"], cwd=work, env=env)
    out = _run([harness, "report", "--from", "latest"], cwd=work, env=env)
    index = Path(out.stdout.strip().splitlines()[-1])
    assert index.is_file() and index.is_relative_to(tmp_path / "reports")
    html = index.read_text(encoding="utf-8")
    assert "<html" in html and "stability" in html.lower()
