"""The presentation kit: what an experiment's report section is made of, below the experiments.

An experiment's folder builds its section from these and names it as its `section` attribute
(`harness.experiments.base.Experiment`), the one way a section is registered; the report
(`harness.report`) only assembles them in order. Modules:
- `elements`: the document model (sections, tables as data, cells, data links) and formatting;
- `view`: `RunView`, the saved run as a section reads it;
- `section`: `SectionSpec` (title, intro, builder, keys, scoreboard columns), the generic table
  section, the judged rows of a summary;
- `figure_style` (one colour and marker per method, panels, log axes), `figure_svg` (checked,
  deterministic SVG), `svg_paths` (compact path data), `figure_cache` (figures kept on disk).

This package re-exports the names a section module uses.
"""

from harness.kit.elements import (
    CSV_DIGITS,
    FAIL,
    HIDDEN_COLUMNS,
    MARK,
    NONE,
    NOTE_COLUMNS,
    PASS,
    Block,
    Download,
    Row,
    Section,
    SectionTimer,
    Table,
    TextCell,
    anchor,
    csv_download,
    df_table,
    first_sentence,
    fmt,
    is_missing,
    status_cell,
    text_cell,
    yes_no,
)
from harness.kit.figure_style import Palette
from harness.kit.figure_svg import Figure, check_svg, to_svg
from harness.kit.section import (
    VERDICT_COLUMNS,
    Measure,
    ScoreColumn,
    SectionSpec,
    generic_section,
    missing,
    skip_note,
    summary_verdicts,
)
from harness.kit.view import RunView

__all__ = ["CSV_DIGITS", "FAIL", "HIDDEN_COLUMNS", "MARK", "NONE", "NOTE_COLUMNS", "PASS", "Block",
           "Download", "Row", "Section", "SectionTimer", "Table", "TextCell", "anchor", "csv_download",
           "df_table", "first_sentence", "fmt", "is_missing", "status_cell", "text_cell", "yes_no",
           "Palette", "Figure", "check_svg", "to_svg", "VERDICT_COLUMNS", "Measure", "ScoreColumn",
           "SectionSpec", "generic_section", "missing", "skip_note", "summary_verdicts", "RunView"]
