"""The diffrax example project (examples/diffrax-claims): a real JAX integrator library's solvers,
wrapped with `StateStepper(backend="jax")`, checked against their documented orders,
reversibility and symplecticity by the harness's pytest plugin, and a mutant of its Tsitouras
5(4) tableau refuted. Run by pytest in a subprocess, as the library's own test suite would be.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("diffrax", reason="diffrax is the optional extra `jax` (pinned in requirements.txt)")

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "diffrax-claims"


@pytest.mark.slow
def test_every_diffrax_solver_keeps_its_documented_claims_and_a_mutant_fails():
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    out = subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "harness.pytest_plugin", "-p", "no:cacheprovider",
         "-q", "--rootdir", str(EXAMPLE), str(EXAMPLE / "tests")],
        cwd=EXAMPLE, env=env, capture_output=True, text=True, timeout=1200,
    )
    assert out.returncode == 0, out.stdout[-6000:] + out.stderr[-3000:]
    assert " passed" in out.stdout and "failed" not in out.stdout
