"""CSV files: every SQL result the report used, in its long form with all columns.

These are the queryable numbers behind the tables (one file per ``reports/sql/<name>.sql``);
list values are written as JSON arrays.
"""

from __future__ import annotations

import csv
import io
import json
from typing import Any

from reports.views import Result


def _plain(v: Any) -> Any:
    if isinstance(v, (list, tuple, dict)):
        return json.dumps(v, default=str)
    return v


def result_csv(result: Result) -> str:
    """The result as CSV text: a header row of its columns, then every row (lists and dicts as JSON)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(result.columns)
    for row in result.rows:
        w.writerow([_plain(v) for v in row])
    return buf.getvalue()
