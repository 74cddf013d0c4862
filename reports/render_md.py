"""The Markdown report: the same tables as the HTML page, plots as SVG files beside it."""

from __future__ import annotations

from reports.model import Report, Table, format_value


def _escape(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def table_md(t: Table) -> str:
    """One table as a Markdown heading, its note in italics, and a pipe table (numbers right-aligned); "(no rows)" when empty."""
    lines = [f"### {t.title}", ""]
    if t.note:
        lines += [f"_{_escape(t.note)}_", ""]
    if not t.rows:
        return "\n".join(lines + ["(no rows)", ""])
    lines.append("| " + " | ".join(_escape(c.header) for c in t.columns) + " |")
    lines.append("|" + "|".join("---" if c.kind in ("text", "list") else "---:" for c in t.columns) + "|")
    for row in t.rows:
        lines.append("| " + " | ".join(_escape(format_value(c.kind, row.get(c.key))) for c in t.columns) + " |")
    lines.append("")
    return "\n".join(lines)


def render_md(report: Report, plot_dir: str | None = "plots") -> str:
    """``plot_dir``: where the SVG files are, relative to the Markdown file (None: no images)."""
    out = [f"# {report.title}", "", "Run folders: " + ", ".join(f"`{d}`" for d in report.run_dirs), ""]
    if report.skipped:
        out += ["**Unreadable part files were skipped:**", ""]
        out += [f"- `{s.path}`: {_escape(s.error)}" for s in report.skipped]
        out.append("")
    for s in report.sections:
        out += [f"## {s.title}", ""]
        if s.intro:
            out += [s.intro, ""]
        if plot_dir is not None:
            for p in s.plots:
                out += [f"![{p.title}]({plot_dir}/{p.name}.svg)", ""]
        for t in s.tables:
            out.append(table_md(t))
    if report.viewer_episodes:
        out += ["## Episode viewer", "", "In report.html: " + ", ".join(f"`{e}`" for e in report.viewer_episodes), ""]
    return "\n".join(out)
