"""The side-by-side section: each N-body problem's steppers at one step and final time, beside the
gate's order, the energy drift class and the longest round trip."""

from __future__ import annotations

import pandas as pd

from harness.kit import RunView, Section, SectionSpec, df_table

__all__ = ["SECTION"]

_INTRO = (
    "Every stepper that runs a gravitational N-body problem, at the problem's step h to the same "
    "final time T (its convergence horizon): the relative error at T, the evaluations and the "
    "wall time (one work-precision point), beside its claimed and measured order (the CI gate's "
    "convergence cell), its energy drift class (energy experiment; its step count is shown) and "
    "its longest round trip (reversibility experiment). Integrators from other libraries "
    "(implementation column) and the built-ins share the rows."
)


def _joined(view: RunView) -> pd.DataFrame:
    """The side-by-side summary joined with the gate, the energy and the reversibility rows."""
    side = view.summary("side-by-side")
    if side is None or side.empty:
        return pd.DataFrame()
    out = side.copy()
    gate = view.gate() if view.has("convergence") else pd.DataFrame()
    if len(gate) and "problem" in gate:
        g = gate[gate.problem != "(any)"][["stepper", "problem", "claimed_order", "measured_order",
                                            "verdict", "outcome", "expected_order"]]
        out = out.merge(g, on=["stepper", "problem"], how="left")
    energy = view.summary("energy") if view.has("energy") else pd.DataFrame()
    if len(energy) and "drift_class" in energy:
        e = energy[["stepper", "problem", "steps", "drift_class", "max_rel_energy_error"]].rename(
            columns={"steps": "energy_steps"})
        out = out.merge(e.drop_duplicates(["stepper", "problem"]), on=["stepper", "problem"], how="left")
    rev = view.summary("reversibility") if view.has("reversibility") else pd.DataFrame()
    if len(rev) and "verdict" in rev:
        r = rev.sort_values("steps").drop_duplicates(["stepper", "problem"], keep="last")
        r = r[["stepper", "problem", "steps", "verdict", "return_error_ulps"]].rename(
            columns={"steps": "round_trip_steps", "verdict": "round_trip"})
        out = out.merge(r, on=["stepper", "problem"], how="left")
    for c in ("energy_steps", "round_trip_steps"):  # counts, shown whole (NaN where not run)
        if c in out:
            out[c] = out[c].map(lambda v: "—" if pd.isna(v) else str(int(v)))
    return out


def build(view: RunView, sec: Section) -> None:
    """One table per N-body problem: each stepper's point beside its other experiments' verdicts."""
    table = _joined(view)
    if table.empty:
        sec.note("The side-by-side experiment has no results in this run.", cls="warning")
        return
    cols = [("stepper", "stepper"), ("implementation", "implementation"),
            ("claimed_order", "claimed order"), ("measured_order", "measured order"),
            ("outcome", "gate"), ("drift_class", "drift class"), ("energy_steps", "drift: steps"),
            ("round_trip", "round trip"), ("round_trip_steps", "round trip: steps"),
            ("return_error_ulps", "return error (ulps)"), ("h", "h"), ("t_end", "T"),
            ("error", "rel. error at T"), ("evals", "evaluations"), ("wall_s", "wall s")]
    cols = [c for c in cols if c[0] in table]
    for problem, g in table.groupby("problem", sort=False):
        g = g.sort_values(["implementation", "stepper"], kind="stable")
        sec.table(df_table(g, cols, f"{problem}: same step and final time", experiment="side-by-side",
                           status=None))


SECTION = SectionSpec("side-by-side", title="N-body integrators side by side", intro=_INTRO, build=build)
