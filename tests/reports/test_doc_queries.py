"""The five queries in the README run over the known run and print what the page shows."""

from __future__ import annotations

import io
import re
from pathlib import Path

from pipeline.cli.sql import sql_main

DOC = Path(__file__).resolve().parents[2] / "README.md"


def _examples() -> list[tuple[str, list[str]]]:
    text = DOC.read_text()
    pairs = re.findall(r"```sql\n(.*?)```\n```\n(.*?)```", text, re.S)
    return [(sql, [line for line in out.splitlines() if line != "..."]) for sql, out in pairs]


def test_documented_queries_print_the_documented_rows(run_a):
    examples = _examples()
    assert len(examples) == 5
    for sql, shown in examples:
        out, err = io.StringIO(), io.StringIO()
        assert sql_main([str(run_a), sql], stdout=out, stderr=err) == 0, err.getvalue()
        printed = out.getvalue().splitlines()
        assert printed[:2] == shown[:2], sql  # header and rule
        for line in shown[2:]:
            assert line in printed, f"{line!r} not printed by:\n{sql}"
