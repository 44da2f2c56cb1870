"""The stability section: region boundaries per family, the h omega limits, probe against formula."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from harness import tolerances as tol
from harness.experiments.stability.figures import hw_limits_figure, stability_overlay_figure
from harness.kit import Measure, RunView, ScoreColumn, Section, SectionSpec, anchor, df_table, fmt
from harness.kit.view import rows_of


def _stability_score(view: RunView, stepper: str) -> tuple[list[tuple[str, str]], bool]:
    s = rows_of(view, "stability", stepper)
    if s.empty:
        return [("—", "")], False
    r = s.iloc[0]
    href = "#" + anchor("stability", stepper, r["problem"])
    if r.get("form") == "newtonian":
        return [("hω ≤ ", ""), (fmt(r.get("hw_limit"), 4), href)], True
    re_iv, im_iv = float(r.get("real_interval")), float(r.get("imag_interval"))
    re_t = "unbounded" if np.isinf(re_iv) else f"[−{fmt(re_iv, 4)}, 0]"
    im_t = "unbounded" if np.isinf(im_iv) else f"±{fmt(im_iv, 4)}"
    return [("real ", ""), (re_t, href), ("; imag ", ""), (im_t, href)], True


def stability(view: RunView, sec: Section) -> None:
    """Add the stability figures and tables to `sec`, read from `view`."""
    rows = view.rowtable("stability")
    summ = view.summary("stability")
    first = rows[rows["kind"] == "grid"] if "kind" in rows else pd.DataFrame()
    if len(first):
        sec.figure(stability_overlay_figure(first, view.palette),
                   "Boundaries |R(hλ)| = 1 of the first-order methods, one panel per family.")
    sec.figure(hw_limits_figure(summ, view.palette),
               "Largest stable hω of each Newtonian stepper on the harmonic oscillator; hatched "
               "bars are unbounded within the search limit.")
    s = summ.assign(agrees=summ["analytic_agrees"].map(
        lambda v: "—" if v is None or (isinstance(v, float) and math.isnan(v)) else ("yes" if v else "NO")))
    cols = [("stepper", "stepper"), ("problem", "problem"), ("form", "form"),
            ("real_interval", "real (probe)"), ("analytic_real_interval", "real (formula)"),
            ("imag_interval", "imag (probe)"), ("analytic_imag_interval", "imag (formula)"),
            ("hw_limit", "hω (probe)"), ("analytic_hw_limit", "hω (formula)"),
            ("hw_bands", "unstable hω bands (exact)"), ("agrees", "probe = formula"),
            ("verdict", "verdict"), ("message", "why")]
    sec.table(df_table(s, cols, "Per stepper: stability intervals, probe against formula (real "
                       "[−x, 0], imaginary [−y, y])", experiment="stability", digits=8))


SECTION = SectionSpec(
    "stability", title="Stability",
    intro=("Linear stability measured from the outside: one step of y' = λy over a grid of "
           "complex hλ (first-order methods), or of x'' = −ω²x (Newtonian methods), compared "
           "with the formula from the coefficients. Each panel overlays one family's boundaries "
           "|R(hλ)| = 1 with the stable side shaded; the bars give the first instability in hω, "
           "and the table lists every unstable hω band, found exactly on the propagator's "
           "polynomials (narrow resonance bands near hω = kπ included)."),
    measures=(Measure("real_interval", "real stability interval", rtol=tol.REPORT_CHANGE_RTOL),
              Measure("imag_interval", "imaginary stability interval", rtol=tol.REPORT_CHANGE_RTOL),
              Measure("hw_limit", "hω limit", rtol=tol.REPORT_CHANGE_RTOL)),
    score=(ScoreColumn("stability (probe)", _stability_score),),
    build=stability,
)
