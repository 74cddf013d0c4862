"""The planned units of each run folder (its plan.json), loaded into ``planned_units`` for the coverage table."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import duckdb
import pyarrow as pa
import yaml

#: the plan a run folder keeps (pipeline.store.PLAN_FILE) and its sweep file (SPEC_FILE)
PLAN_FILE = "plan.json"
SPEC_FILE = "spec.yaml"
#: the model-string prefix of the pipeline's test-double models (pipeline.spec.OFFLINE_PREFIX)
_TEST_DOUBLE_PREFIX = "offline/"


def _test_double_models(run_dir: Path) -> dict[str, bool]:
    """Model label -> test double, from the run folder's sweep file ({} when it cannot be read)."""
    try:
        data = yaml.safe_load((run_dir / SPEC_FILE).read_text(encoding="utf-8"))
        out = {}
        for m in data.get("models") or []:
            model = str(m["model"])
            out[str(m.get("label") or model)] = model.startswith(_TEST_DOUBLE_PREFIX)
        return out
    except Exception:  # noqa: BLE001 - no sweep file, or not one: the episode rows tell instead
        return {}


#: the columns of ``planned_units`` (reports/sql/views.sql), in order
_PLAN_COLUMNS = ("run_dir", "run_id", "unit_id", "label", "method", "model", "instance_id", "sampling_seed", "test_double")


def _read_plan(path: Path) -> list[tuple[str, str, Any, str, str, Any]]:
    """(unit, arm label, method, model, instance, sampling seed) of each unit of a plan.json; OSError, ValueError,
    KeyError or TypeError when it cannot be read as one. A plan written before schema version 4 names the
    sampling seed ``seed``."""
    units = json.loads(path.read_text(encoding="utf-8"))["units"]
    # plan.json's "method" is the arm's label; "method_name" the method (schema version 2)
    return [
        (
            str(u["unit_id"]),
            str(u["method"]),
            u.get("method_name"),
            str(u["model"]),
            str(u.get("instance_id") or ""),
            u.get("sampling_seed", u.get("seed")),
        )
        for u in units
    ]


def _insert(con: duckdb.DuckDBPyConnection, cols: dict[str, list[Any]]) -> None:
    """Insert the plan rows into ``planned_units`` through a registered Arrow table."""
    types = {"sampling_seed": pa.int64(), "test_double": pa.bool_()}
    table = pa.table({k: pa.array(v, type=types.get(k, pa.string())) for k, v in cols.items()})  # noqa: F841
    con.register("_planned_units", table)
    try:
        con.execute("INSERT INTO planned_units SELECT * FROM _planned_units")
    finally:
        con.unregister("_planned_units")


def load_plans(con: duckdb.DuckDBPyConnection) -> dict[str, str]:
    """Fill ``planned_units`` (reports/sql/views.sql) from each run folder's plan.json, read
    here in Python (the connection itself reaches no file). Returns run folder -> how its plan
    was read (``plan.json``, ``no plan.json``, ``unreadable plan.json: ...``). Done once per
    connection; a folder without a readable plan is left to the coverage query's fallback."""
    if (con.execute("SELECT count(*) FROM planned_units").fetchone() or (0,))[0]:
        return {}
    cols: dict[str, list[Any]] = {k: [] for k in _PLAN_COLUMNS}
    how: dict[str, str] = {}
    for run_dir, run_id in con.execute("SELECT run_dir, run_json_id FROM run_dirs ORDER BY run_dir").fetchall():
        try:
            rows = _read_plan(Path(run_dir) / PLAN_FILE)
        except FileNotFoundError:
            how[run_dir] = f"no {PLAN_FILE}"
            continue
        except (OSError, ValueError, KeyError, TypeError) as exc:
            how[run_dir] = f"unreadable {PLAN_FILE}: {type(exc).__name__}"
            continue
        doubles = _test_double_models(Path(run_dir))
        how[run_dir] = PLAN_FILE
        for uid, label, method, model, inst, sampling_seed in rows:
            for k, v in zip(
                cols,
                (
                    run_dir,
                    run_id,
                    uid,
                    label,
                    method if isinstance(method, str) else None,
                    model,
                    inst,
                    sampling_seed if isinstance(sampling_seed, int) and not isinstance(sampling_seed, bool) else None,
                    doubles.get(model),
                ),
            ):
                cols[k].append(v)
    if cols["unit_id"]:
        _insert(con, cols)
    return how
