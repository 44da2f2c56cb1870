"""The evals-per-step experiment's report section: declared against counted evaluations, one
row per stepper and problem, and a scoreboard column."""

from harness.kit import ScoreColumn, SectionSpec, anchor, df_table, fmt
from harness.kit.view import rows_of

NAME = "evals-per-step"


def _score(view, stepper):
    s = rows_of(view, NAME, stepper)
    if s.empty:
        return [("—", "")], False
    r = s.iloc[0]
    per = float(r["evals"]) / float(r["n_steps"])
    return [(fmt(per, 3), "#" + anchor(NAME, stepper, r["problem"]))], True


def build(view, sec):
    """The summary as one table: counted evaluations beside n_steps times the declared cost."""
    summ = view.summary(NAME)
    sec.note("Counted right-hand-side evaluations over n steps; a method is as declared when they "
             "lie between n and n + 1 times its declared cost per step.")
    cols = [("stepper", "stepper"), ("problem", "problem"), ("n_steps", "steps"),
            ("evals", "evaluations counted"), ("declared", "declared per step"), ("verdict", "verdict")]
    sec.table(df_table(summ, cols, f"Per cell: {len(summ)} counts", experiment=NAME))


SECTION = SectionSpec(
    NAME, title="Evaluations per step",
    intro=("Right-hand-side evaluations counted over a fixed number of steps against the "
           "stepper's declared cost per step. Each row is as declared or not."),
    build=build, score=[ScoreColumn("evaluations per step (counted)", _score)],
)
