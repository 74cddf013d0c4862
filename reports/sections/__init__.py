"""The report's sections under one name (``sections.overview(q)`` ...): each section's module, re-exported.

Numbers come only from the SQL in ``reports/sql/`` (the cost permutation test is computed from
the per-pair differences and their instances that ``paired_methods.sql`` returns). Each table's
note names its intervals and tests from the rows shown (:mod:`reports.stat_notes`). Pivoting a long SQL result into
the paper's layout (methods x splits) happens here; the long results themselves go to CSV.

Modules: :mod:`~reports.sections.common` (the query runner and pivot helpers),
:mod:`~reports.sections.plans` (planned units from plan.json), and one per section:
:mod:`~reports.sections.overview`, :mod:`~reports.sections.success`, :mod:`~reports.sections.costs`,
:mod:`~reports.sections.context`, :mod:`~reports.sections.trees`, :mod:`~reports.sections.failures`,
:mod:`~reports.sections.coding` (only for a run with coding episodes).
"""

from __future__ import annotations

from reports.sections.coding import coding
from reports.sections.common import PAPER_POINTER, Query, make_query
from reports.sections.context import context
from reports.sections.costs import costs
from reports.sections.failures import MODE_NOTE, failures
from reports.sections.overview import overview
from reports.sections.plans import PLAN_FILE, SPEC_FILE, load_plans
from reports.sections.success import success
from reports.sections.trees import trees

__all__ = [
    "MODE_NOTE",
    "PAPER_POINTER",
    "PLAN_FILE",
    "SPEC_FILE",
    "Query",
    "coding",
    "context",
    "costs",
    "failures",
    "load_plans",
    "make_query",
    "overview",
    "success",
    "trees",
]
