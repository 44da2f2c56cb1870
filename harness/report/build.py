"""`harness report`: run (or reuse) every experiment, save the run, write one self-contained HTML file.

Steps of `build_report`:
1. Every report experiment runs over the selected steppers x problems through
   `harness.runner.run_experiments` (finished cells come from the cell cache, so a rerun, or a
   run after `kill -9`, recomputes only what is missing); one progress display for all of them.
2. The results are saved with their provenance (`harness.store.save_run`) and read back
   (`load_run`), so the report shows exactly what the results directory holds.
3. The sections (`harness.report.sections`, one per experiment of the registry) turn the tables
   into HTML tables, inline SVG figures and embedded CSV links; the earlier run (the newest one
   before this in the results directory, or `compare`) gives the "what changed" section
   (`harness.report.compare`); Jinja2 renders `templates/report.html.j2` with autoescaping on.
4. The report is assembled in a hidden staging directory and renamed into
   `<reports>/<run id>/index.html` (run id = `<UTC timestamp>-<short git sha>`), with the
   verdicts it judged beside it (`verdicts.csv`, what a later report compares with), then
   `<reports>/latest` is swapped to point at it (a relative symlink replaced with `os.replace`;
   where symlinks are not possible, a copied directory swapped by renames).

The reports directory is `output`, else `HARNESS_REPORTS_DIR`, else `<project>/reports` (the
current directory's `reports/` when the package is installed elsewhere).
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import shutil
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import jinja2

from harness import __version__, registry
from harness.errors import InputError

# The experiments a report runs, in the order of its sections: the one list in
# harness/experiments/__init__.py.
from harness.experiments import EXPERIMENT_NAMES as REPORT_EXPERIMENTS
from harness.experiments.base import ENTRY_POINT_EXPERIMENTS
from harness.kit import Palette, RunView
from harness.kit.figure_svg import page_css, short_classes, short_ids
from harness.progress import Progress
from harness.provenance import default_directory
from harness.report.compare import VERDICTS_FILE, load_previous
from harness.report.sections import build_sections
from harness.runner import check_names, check_plugins, run_experiments
from harness.store import StoredRun, load_run, resolve_run, save_run
from harness.store.schema import SAFE_NAME

__all__ = ["build_report", "write_report", "rerender_report", "report_experiments", "reports_root",
           "render_html", "run_view"]



def report_experiments() -> list[str]:
    """The experiments a report runs, in the order of its sections: the one experiment list
    (`harness.experiments.EXPERIMENT_NAMES`), then those other distributions registered through
    the `harness.experiments` entry points.

    Returns
    -------
    list of str: experiment names.
    """
    return [*REPORT_EXPERIMENTS, *ENTRY_POINT_EXPERIMENTS]

TEMPLATE = "report.html.j2"


def reports_root(output: str | os.PathLike | None = None) -> Path:
    """Where reports are written: `output`, `HARNESS_REPORTS_DIR`, or `<project>/reports`.

    Parameters
    ----------
    output : path, optional, the directory asked for.

    Returns
    -------
    Path: not created here; `InputError` for an empty path, a NUL byte or an existing file.
    """
    output = default_directory(output, "HARNESS_REPORTS_DIR", "reports")
    if not isinstance(output, str | os.PathLike) or not os.fspath(output) or "\x00" in os.fspath(output):
        raise InputError(f"`output` must be a directory path, got {output!r}")
    path = Path(output)
    if path.exists() and not path.is_dir():
        raise InputError(f"`output` must be a directory, but {str(path)!r} is a file")
    return path


def _say(progress: Progress, message: str) -> None:
    if progress.mode == "off":
        return
    progress.stream.write(f"report: {message}\n")
    progress.stream.flush()


def render_html(context: dict[str, Any]) -> str:
    """Render the report template with autoescaping on (every text is escaped; only figure SVG,
    checked by `figures.check_svg`, is inserted as markup).

    Parameters
    ----------
    context : dict, the template's variables (all must be present: undefined ones raise).

    Returns
    -------
    str: the HTML page.
    """
    env = jinja2.Environment(
        loader=jinja2.PackageLoader("harness.report", "templates"),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        trim_blocks=False,
        lstrip_blocks=False,
    )
    return env.get_template(TEMPLATE).render(**context)


def _write_report(root: Path, report_id: str, html: str, extra: dict[str, str] | None = None) -> Path:
    """Write `<root>/<report id>/index.html` (and the `extra` files) atomically (staging
    directory, then rename) and point `<root>/latest` at it. Returns the index.html path."""
    if not SAFE_NAME.match(report_id) or report_id.strip(".") == "":  # a path only from a safe id
        raise InputError(f"report id {report_id[:80]!r} must use letters, digits and _.+- only")
    root.mkdir(parents=True, exist_ok=True)
    final = root / report_id
    n = 2
    while final.exists():
        final = root / f"{report_id}-{n}"
        n += 1
    staging = root / f".staging-{final.name}@{os.getpid()}"
    if staging.exists():
        shutil.rmtree(staging)
    staging.mkdir()
    try:
        index = staging / "index.html"
        with open(index, "w", encoding="utf-8") as fh:
            fh.write(html)
            fh.flush()
            os.fsync(fh.fileno())
        for name, text in (extra or {}).items():
            with open(staging / name, "w", encoding="utf-8") as fh:
                fh.write(text)
                fh.flush()
                os.fsync(fh.fileno())
        os.rename(staging, final)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    _point_latest(root, final.name)
    return final / "index.html"


def _point_latest(root: Path, name: str) -> None:
    latest = root / "latest"
    tmp = root / f".latest-{os.getpid()}"
    with contextlib.suppress(FileNotFoundError):
        if tmp.is_symlink() or tmp.is_file():
            tmp.unlink()
        elif tmp.is_dir():
            shutil.rmtree(tmp)
    if not (latest.exists() and latest.is_dir() and not latest.is_symlink()):
        try:
            os.symlink(name, tmp, target_is_directory=True)
            os.replace(tmp, latest)  # atomic: readers see the old or the new target
            return
        except OSError:
            with contextlib.suppress(OSError):
                tmp.unlink()
    # a real directory (or no symlinks here): copy, then swap by renames
    shutil.copytree(root / name, tmp)
    old = root / f".latest-old-{os.getpid()}"
    if latest.is_symlink() or latest.is_file():
        latest.unlink()
    elif latest.exists():
        os.rename(latest, old)
    os.rename(tmp, latest)
    shutil.rmtree(old, ignore_errors=True)


def _check_flag(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise InputError(f"`{name}` must be True or False, got {value!r}")
    return value


def build_report(
    steppers: Sequence[str] | None = None,
    problems: Sequence[str] | None = None,
    quick: bool = False,
    jobs: int | None = None,
    scheduler: str | None = None,
    fresh: bool = False,
    plugins: Sequence[str | os.PathLike] = (),
    output: str | os.PathLike | None = None,
    *,
    cache_dir: str | os.PathLike | None = None,
    results_root: str | os.PathLike | None = None,
    cell_timeout: float | None = None,
    progress: Progress | bool | str | None = None,
    compare: str | os.PathLike | None = None,
) -> Path:
    """Run every report experiment over `steppers` x `problems`, save the run, and write the
    HTML report. Failed cells do not stop the report: they are listed in it.

    Parameters
    ----------
    steppers, problems : sequence of str, optional, registered names (None: the whole registry).
    quick : bool, optional, every experiment's CI-sized settings (every section is still there).
    jobs, scheduler, fresh, plugins, cell_timeout : as in `harness.runner.run_experiment`.
    output : path, optional, the reports directory (see `reports_root`).
    cache_dir : path, optional, the cell cache.
    results_root : path, optional, where runs are saved.
    progress : Progress, bool or str, optional, as in the runner (None: a bar on a terminal,
        plain lines otherwise).
    compare : str or path, optional, the earlier run "what changed" compares with (default the
        newest older run in the results directory).

    Returns
    -------
    Path: the report's index.html.
    """
    started = time.perf_counter()
    quick = _check_flag("quick", quick)
    fresh = _check_flag("fresh", fresh)
    root = reports_root(output)

    plugin_paths = check_plugins(plugins)
    for p in plugin_paths:
        registry.load_plugin(p)
    stepper_names = check_names("steppers", steppers)
    problem_names = check_names("problems", problems)
    if not stepper_names:
        raise InputError("`steppers` must name at least one stepper")
    if not problem_names:
        raise InputError("`problems` must name at least one problem")
    experiments = report_experiments()
    if compare is not None:
        resolve_run(compare, root=results_root)  # a bad --compare fails before anything runs

    if isinstance(progress, Progress):
        bar, own = progress, False
    else:
        mode = {None: "auto", True: "auto", False: "off"}.get(progress, progress)  # type: ignore[arg-type]
        bar, own = Progress(0, "report", mode=mode), True
    try:
        results = run_experiments(
            experiments, stepper_names, problem_names, quick=quick, jobs=jobs,
            scheduler=scheduler, fresh=fresh, cache_dir=cache_dir, plugins=plugin_paths,
            cell_timeout=cell_timeout, progress=bar,
        )
    finally:
        if own:
            bar.close()
    t_run = time.perf_counter() - started

    t0 = time.perf_counter()
    run_dir = save_run(results, root=results_root, config={
        "command": "report", "quick": quick, "steppers": stepper_names, "problems": problem_names,
        "plugins": plugin_paths, "jobs": jobs, "scheduler": scheduler, "fresh": fresh,
        "cell_timeout": cell_timeout, "experiments": experiments,
    })
    # the packed experiments' rows are already as their files read back: not decoded again
    stored = load_run(run_dir, stored_rows={
        name: res.rows for name, res in results.items() if getattr(res, "rows_stored", False)})
    t_save = time.perf_counter() - t0
    _say(bar, f"results saved in {run_dir}")
    path = write_report(stored, output=root, progress=bar, build_s={
        "experiments (run or load from cache)": t_run, "save and reload results": t_save},
        compare=compare, compare_default=True)
    _say(bar, f"report written in {time.perf_counter() - started:.1f} s: {path}")
    return path


def rerender_report(run: str | os.PathLike | None, *, output: str | os.PathLike | None = None,
                    compare: str | os.PathLike | None = None, grid_options: Sequence[str] = ()) -> Path:
    """`harness report --from RUN`: write the report of a saved run again (id, path, 'latest'),
    nothing measured; the steppers, problems and mode are the run's own, so `grid_options` (the
    measuring options given with it) are refused.

    Parameters
    ----------
    run : str, path or None, the saved run (None: the newest).
    output : path, optional, the reports directory.
    compare : str or path, optional, the earlier run to compare with (resolved beside `run`).
    grid_options : sequence of str, the measuring options given (any is an `InputError`).

    Returns
    -------
    Path: the report's index.html.
    """
    if grid_options:
        raise InputError(f"`--from` re-renders a saved run as it was measured; it takes no "
                         f"{', '.join(grid_options)}")

    stored = load_run(run)
    if compare is not None:
        resolve_run(compare, root=stored.path.parent)
    return write_report(stored, output=output, compare=compare, compare_default=True)


def run_view(stored: Any, *, need_steppers: bool = True) -> Any:
    """The RunView of a saved run: its tables, and the steppers, problems and mode of its own
    configuration. Plugin files its meta.json names are never imported (opening someone else's
    results directory must not run their code): a plugin's steppers are shown when this process
    loaded it (the run it just measured, or `harness report --from RUN --plugin FILE`); with
    `need_steppers`, a run whose plugin steppers are not loaded is an `InputError` saying so.

    Parameters
    ----------
    stored : StoredRun, the loaded run.
    need_steppers : bool, optional, keyword-only (default True).

    Returns
    -------
    RunView
    """
    meta = stored.meta
    cfg = meta.get("config", {}).get("run", {})
    stepper_names = list(cfg.get("steppers") or registry.steppers.names())
    problem_names = list(cfg.get("problems") or registry.problems.names())
    known = [n for n in stepper_names if n in registry.steppers]
    plugins = [str(p) for p in cfg.get("plugins", []) or []]
    if need_steppers and plugins and len(known) < len(stepper_names):
        missing = [n for n in stepper_names if n not in registry.steppers]
        raise InputError(
            f"run {stored.run_id!r} was measured with plugin file(s) {plugins}, whose steppers "
            f"{missing[:5]} are not loaded; files named by a results directory are never "
            "imported: pass them with --plugin FILE to re-render it")
    infos = {n: registry.get_stepper(n).info for n in known}
    return RunView(
        rows=dict(stored.rows), summaries=dict(stored.summaries), meta=meta,
        steppers=known, problems=[p for p in problem_names if p in registry.problems],
        infos=infos, origins={n: registry.steppers.origin(n) for n in known},
        quick=bool(cfg.get("quick", False)),
        palette=Palette(known, {n: i.family for n, i in infos.items()}), run_id=stored.run_id,
    )


def write_report(
    run: Any,
    *,
    output: str | os.PathLike | None = None,
    progress: Progress | None = None,
    build_s: dict[str, float] | None = None,
    compare: str | os.PathLike | None = None,
    compare_default: bool = True,
) -> Path:
    """Write the HTML report of a saved run (a `harness.store.StoredRun`, a run id, a path, or
    None for the newest) into the reports directory; return its index.html path. The steppers,
    problems, plugins and mode are the run's own (from its meta.json). `compare` names the
    earlier run for "what changed"; without it, with `compare_default`, the newest older run
    in the same results directory.

    Parameters
    ----------
    run : StoredRun, str, path or None, the run.
    output : path, optional, the reports directory.
    progress : Progress, optional, where build phases are reported.
    build_s : dict of str to float, optional, seconds already spent (measuring), shown in
        Provenance.
    compare : str or path, optional, the earlier run.
    compare_default : bool, optional, fall back to the newest older run (default True).

    Returns
    -------
    Path: the report's index.html.
    """
    stored = run if isinstance(run, StoredRun) else load_run(run)
    root = reports_root(output)
    bar = progress if progress is not None else Progress(0, "report", mode="off")
    meta = stored.meta
    view = run_view(stored)
    previous = None
    if compare is not None or compare_default:
        previous = load_previous(compare, results_root=stored.path.parent, reports_root=root,
                                 current=stored.run_id,
                                 view_factory=lambda s: run_view(s, need_steppers=False))
        if previous is not None:
            _say(bar, f"comparing with run {previous.run_id}")
    t0 = time.perf_counter()
    sections, statuses, counts = build_sections(
        view, run_id=stored.run_id, results_path=str(stored.path), build_s=dict(build_s or {}),
        previous=previous, progress=lambda name: _say(bar, f"section {name}"),
    )
    t_sections = time.perf_counter() - t0
    git = meta["provenance"].get("git", {})
    totals = meta.get("totals", {})
    headline = (f"{len(view.steppers)} steppers × {len(view.problems)} problems; "
                f"{totals.get('cells', 0)} cells ({totals.get('computed', 0)} computed, "
                f"{totals.get('cached', 0)} from cache, {totals.get('failed', 0)} failed) in "
                f"{len(meta.get('experiments', {}))} experiments.")

    blocks = [b for sec in sections for b in sec.blocks if b.figure is not None]
    svgs, figure_css = short_classes([b.figure.svg for b in blocks], page_css(b.figure for b in blocks))
    for b, svg in zip(blocks, svgs, strict=True):
        b.figure = dataclasses.replace(b.figure, svg=svg)
    html = short_ids(render_html({
        "sections": sections, "figure_css": figure_css, "run_id": stored.run_id,
        "generated": meta.get("created_utc", ""),
        "commit": git.get("short_sha") or "unknown", "dirty": bool(git.get("dirty")),
        "mode": "quick mode (CI-sized settings)" if view.quick else "full settings",
        "headline": headline, "version": __version__, "results_path": str(stored.path),
    }))
    verdicts_csv = counts["verdicts"].drop(columns=["anchor"]).to_csv(index=False)
    path = _write_report(root, stored.run_id, html, {VERDICTS_FILE: verdicts_csv})
    _say(bar, f"sections built in {t_sections:.1f} s; {counts['checked']} claims checked, "
              f"{counts['failed']} failed; {len(html) / 1e6:.2f} MB")
    return path
