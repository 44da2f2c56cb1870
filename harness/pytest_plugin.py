"""pytest plugin: a library's own tests state what its integrator claims, the harness measures it.

Registered through the `pytest11` entry point (installed with this package) or loaded by hand with
`pytest -p harness.pytest_plugin`. It provides the fixture `integrator_claims`, a function with
the signature of `harness.api.check`:

    def test_my_stepper(integrator_claims):
        integrator_claims(my_step, ["harmonic", "kepler-circular"], order=4, symmetric=True,
                          energy="bounded")

A false claim fails the test with the measured table as its message (no traceback into the
harness). The fixture returns the `ClaimReport` (`report.table`: one row per claim and problem,
measured beside claimed); `fail=False` returns it without failing, for a test that inspects it.
`--integrator-claims-full` runs the experiments' full settings instead of their quick ones
(slower, tighter).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

__all__ = ["integrator_claims"]


def pytest_addoption(parser: pytest.Parser) -> None:
    """Add ``--integrator-claims-full`` (measure with the experiments' full settings).

    Parameters
    ----------
    parser : pytest.Parser, pytest's option parser.
    """
    group = parser.getgroup("integrator-claims", "integrator claims checked by the harness")
    group.addoption(
        "--integrator-claims-full",
        action="store_true",
        default=False,
        help="measure claims with the experiments' full settings instead of their quick ones",
    )


@pytest.fixture
def integrator_claims(request: pytest.FixtureRequest) -> Callable[..., Any]:
    """`check(stepper, problems, order=..., symmetric=..., energy=..., **options)`: measures the
    claims (see `harness.api.check`), returns the `ClaimReport`, fails the test when one is false
    (unless `fail=False`).

    Parameters
    ----------
    request : pytest.FixtureRequest, the requesting test (its config tells quick or full settings).

    Returns
    -------
    callable: ``check(stepper, problems, **claims_and_options)`` -> `ClaimReport`.
    """
    # The plugin's one deferred import of a project module (tests/test_import_layers.py allows
    # exactly this one): pytest imports this module at the start of every test run of every
    # project that has the harness installed; the API imports heyoka, pandas and the experiments
    # (~2 s CPU), which only a test that asks for this fixture needs.
    from harness.api import check

    full = bool(request.config.getoption("--integrator-claims-full"))

    def _check(stepper: Any, problems: Any, *, fail: bool = True, **claims: Any):
        claims.setdefault("quick", not full)
        report = check(stepper, problems, raise_on_failure=False, **claims)
        if fail and not report.passed:
            pytest.fail(str(report), pytrace=False)
        return report

    return _check
