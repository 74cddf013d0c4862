"""The paper section's SWE-bench Verified cells: the temperature each arm ran at, read only when a run has them.

Why apart from ``paper_cells.sql``: the paper's SWE-bench protocol (GPT-4.1, temperature 0, each of
the 500 instances once: :func:`reports.paper.swe_mismatch`) needs the arm's temperature, which no
other table checks; a separate query keeps every other report's files as they were (its CSV is
written only for a run with SWE-bench Verified episodes).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from reports import paper
from reports.paper_cells import Cells, arm_protocol

#: the main table's note on SWE-bench Verified rows
SWE_NOTE = (
    "SWE-bench Verified: resolved share of the instances (pass@1); mini_swe arms stand in the ReAct column (the "
    "paper's ReAct baseline is mini-SWE-agent); the paper's numbers are GPT-4.1 (2025-04-14) at temperature 0 "
    "over all 500 instances."
)


def swe_protocol(cells: Cells, cell: dict[str, Any]) -> paper.ArmProtocol:
    """What a SWE-bench Verified cell's arm ran, its temperatures included (``paper_swe.sql``)."""
    temps = next(
        (
            tuple(r["temperatures"])
            for r in cells.q("paper_swe").dicts()
            if (r["model_label"], r["arm_label"]) == (cell["model_label"], cell["arm_label"])
        ),
        (),
    )
    return dataclasses.replace(arm_protocol(cell), temperatures=temps)


def swe_mismatch(cells: Cells, cell: dict[str, Any]) -> str | None:
    """Why the paper's SWE-bench Verified number may not stand beside ``cell``; None when it may."""
    return paper.swe_mismatch(swe_protocol(cells, cell))
