"""Build a report over one or more run folders and write it in the chosen formats.

``build_report`` opens the runs read-only, runs the SQL of every section and the viewer;
``write_report`` lays the result out as Markdown (+ SVG plot files), one HTML page, LaTeX tables
and CSV files under ``out_dir``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from reports import sections
from reports.model import Report
from reports.paper_section import paper_section
from reports.render_csv import result_csv
from reports.render_html import render_html
from reports.render_md import render_md
from reports.render_tex import tex_tables
from reports.run_names import run_names
from reports.viewer import DEFAULT_EPISODES, build_viewer, select_episodes
from reports.views import ReportError, Result, materialize, open_runs_checked

FORMATS = ("md", "html", "tex", "csv")


@dataclass(frozen=True)
class ReportOptions:
    """What ``recap report`` asks for: output formats, the viewer's episodes, the title, and whether only the
    paper section is built."""

    formats: tuple[str, ...] = FORMATS
    #: episodes to show in the viewer; None = a sample of ``viewer_max``
    episodes: tuple[str, ...] | None = None
    viewer_max: int = DEFAULT_EPISODES
    title: str = "recap-eval report"
    #: only the paper section (``recap report --paper``)
    paper_only: bool = False


def parse_formats(text: str) -> tuple[str, ...]:
    """The ``--format`` list (comma-separated, any case, duplicates dropped) as known formats in the order given;
    ReportError for an unknown or empty list."""
    wanted = tuple(dict.fromkeys(f.strip().lower() for f in text.split(",") if f.strip()))
    bad = [f for f in wanted if f not in FORMATS]
    if bad or not wanted:
        raise ReportError(f"unknown report format(s) {', '.join(bad) or '(none given)'}; choose from {', '.join(FORMATS)}")
    return wanted


def build_report(run_dirs: Sequence[str | Path], options: ReportOptions = ReportOptions()) -> Report:
    """Open the runs read-only and run every section's SQL (and the episode viewer when HTML is wanted); the
    connection is closed before returning, so a Report holds only values."""
    con, skipped = open_runs_checked(run_dirs)
    try:
        materialize(con, ("attempts", "episode_modes"))
        results: dict[str, Result] = {}
        q = sections.make_query(con, results)
        ids = (
            select_episodes(con, list(options.episodes) if options.episodes else None, options.viewer_max)
            if "html" in options.formats
            else []
        )
        paper = paper_section(q, results)
        if options.paper_only:
            secs = [paper]
        else:
            secs = [
                sections.overview(q),
                sections.success(q),
                sections.costs(q),
                sections.context(q),
                sections.trees(q),
                sections.failures(q),
            ]
            coding = sections.coding(q, results)  # None for a run without coding episodes
            secs += ([coding] if coding is not None else []) + [paper]
        viewer_html = build_viewer(con, ids, results) if ids else ""
        dirs = [str(r[0]) for r in con.execute("SELECT run_dir FROM run_dirs").fetchall()]
        names = run_names(con.execute("SELECT run_dir, run_json_id FROM run_dirs").fetchall())
    finally:
        con.close()
    return Report(options.title, dirs, skipped, secs, results, viewer_html, ids, names)


def _write(path: Path, text: str) -> None:
    """Write atomically so a reader never sees half a report file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".tmp-{path.name}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def write_report(report: Report, out_dir: str | Path, formats: Sequence[str] = FORMATS) -> list[Path]:
    """Write the formats asked for under ``out_dir`` (report.md with plots/*.svg, report.html, tex/*.tex,
    csv/*.csv); returns the paths written."""
    out = Path(out_dir)
    written: list[Path] = []
    if "md" in formats:
        for s in report.sections:
            for p in s.plots:
                _write(out / "plots" / f"{p.name}.svg", p.svg)
                written.append(out / "plots" / f"{p.name}.svg")
        _write(out / "report.md", render_md(report))
        written.append(out / "report.md")
    if "html" in formats:
        _write(out / "report.html", render_html(report))
        written.append(out / "report.html")
    if "tex" in formats:
        for name, text in tex_tables(report).items():
            _write(out / "tex" / name, text)
            written.append(out / "tex" / name)
    if "csv" in formats:
        for name, result in report.results.items():
            _write(out / "csv" / f"{name}.csv", result_csv(result))
            written.append(out / "csv" / f"{name}.csv")
    return written
