"""LaTeX tables (booktabs), one file per table plus a document that inputs them all."""

from __future__ import annotations

from reports.model import Report, Table, format_value

_SPECIAL = {
    "\\": r"\textbackslash{}",
    "&": r"\&",
    "%": r"\%",
    "$": r"\$",
    "#": r"\#",
    "_": r"\_",
    "{": r"\{",
    "}": r"\}",
    "~": r"\textasciitilde{}",
    "^": r"\textasciicircum{}",
    "–": "--",
    "−": "$-$",
    "·": r"\textperiodcentered{}",
    "…": r"\ldots{}",
    "<": r"$<$",
    ">": r"$>$",
}


def tex_escape(text: str) -> str:
    """``text`` with the characters LaTeX treats as special escaped, so titles and cells print as written."""
    return "".join(_SPECIAL.get(ch, ch) for ch in text)


def table_tex(t: Table) -> str:
    """One table as a booktabs ``table`` environment (labelled ``tab:<name>``, shrunk to the line width when
    wider), its note below."""
    align = "".join("l" if c.kind in ("text", "list") else "r" for c in t.columns)
    lines = [
        "\\begin{table}[ht]",
        "\\centering\\small",
        f"\\caption{{{tex_escape(t.title)}}}",
        f"\\label{{tab:{t.name}}}",
        "\\resizebox{\\ifdim\\width>\\linewidth\\linewidth\\else\\width\\fi}{!}{%",
        f"\\begin{{tabular}}{{{align}}}",
        "\\toprule",
        " & ".join(tex_escape(c.header) for c in t.columns) + " \\\\",
        "\\midrule",
    ]
    for row in t.rows:
        cells = [tex_escape(format_value(c.kind, row.get(c.key))) for c in t.columns]
        if cells and cells[0].startswith("["):  # "\\ [" would read as a line-spacing argument
            cells[0] = "{}" + cells[0]
        lines.append(" & ".join(cells) + " \\\\")
    lines += ["\\bottomrule", "\\end{tabular}}"]
    if t.note:
        lines.append(f"\\par\\footnotesize {tex_escape(t.note)}")
    lines += ["\\end{table}", ""]
    return "\n".join(lines)


def tex_tables(report: Report) -> dict[str, str]:
    """``{file name: content}``: ``<table>.tex`` for each table and ``report.tex`` inputting them."""
    files: dict[str, str] = {}
    body = []
    for s in report.sections:
        body.append(f"\\section*{{{tex_escape(s.title)}}}")
        for t in s.tables:
            files[f"{t.name}.tex"] = table_tex(t)
            body.append(f"\\input{{{t.name}}}")
    files["report.tex"] = "\n".join(
        [
            "\\documentclass{article}",
            "\\usepackage[margin=2cm,landscape]{geometry}",
            "\\usepackage{booktabs,graphicx}",
            f"\\title{{{tex_escape(report.title)}}}\\date{{}}",
            "\\begin{document}\\maketitle",
            *body,
            "\\end{document}",
            "",
        ]
    )
    return files
