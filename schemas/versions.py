"""Parts written under an earlier schema version, mapped to the current one on read.

Every part file carries its schema version in its Arrow metadata (``recap_eval_schema_version``,
:func:`part_version`). A reader takes a part of an *earlier* version when it lacks only columns
added since that version (:func:`missing_fillable`) or renamed since (:func:`stored_names`: the
stored column is read under its new name) and maps its rows with :func:`upgrade`, so
``recap status``, ``recap sql``, ``recap report`` and ``recap show`` read runs written by an
older recap exactly as they would have read them then, plus what can be derived.

Version 1 -> 2, ``episodes`` (documented mapping; everything else is copied as stored):

* ``label``: the stored ``method`` (version 1 kept the arm's label there);
* ``method``: the stored value too, except a label in the form a sweep gives an unlabelled arm
  (``recap``, ``recap[paper]``, ``recap[paper,no_think]``, ``recap[level_3]``), which names
  the method, and the profile and ablation in its brackets
  (:func:`schemas.labels.parse_default_label`);
* ``profile``: from such a label, else null (version 1 did not record it);
* ``ablation``: from such a label, else what the ReCAP settings of ``method_config`` amount to
  (:func:`schemas.labels.ablation_of_config`: ``no_think``, ``level_3`` ...), null for none;
* ``provider_model``: null (version 1 kept only the model's label, in ``model``);
* ALFWorld rows: ``split`` ``valid_unseen``, ``task`` the task type (version 1 had the type
  in ``split`` and ALFRED's long type name in ``task``) - :func:`schemas.labels.place_of`;
* rows without a split (a unit the driver gave up on): ``split``/``task`` from the instance id;
* ``end_reason`` ``infra_error`` where the row records an infrastructure failure
  (:func:`schemas.labels.infra_failure`: an ``llm_error`` of a failed model service, a unit given
  up after its workers died); its ``error`` is kept, so the failure's kind still reads from it.

Version 2 -> 3, ``llm_calls``:

* ``model_name`` (the model's name in the sweep, ``episodes.model``): derived from the stored
  ``deployment``, which version 2 named after the model's label when it had one, else after the
  model string (``model``, ``model@<api_base>``, ``model#<key variable>``, or both): a
  ``deployment`` that is the row's ``model`` or begins with ``model@`` / ``model#`` gives the
  model string (an unlabelled entry's name), any other the label itself; null without a
  deployment (a failed call recorded by the agent, ``model`` empty). A label that itself begins
  with its model string and ``@`` or ``#`` reads as the model string: the one case version 2 did
  not keep apart.

Version 3 -> 4, ``episodes``: ``seed`` renamed ``sampling_seed`` (the unit's sampling seed, the
sweep's ``sampling_seeds``; named apart from an instance's layout seed, the ``@N`` of its id, and
a test double's ``noise_seed``). The values are copied as stored.

Version 4 -> 5 (tool calls, issue 28):

* ``messages``: ``tool_call_id`` (the call a ``tool`` message answers) and ``tool_calls`` (an
  assistant message's calls as JSON) are null in every row of an earlier part: no method of
  version 4 or earlier called tools, so null is what those rows would have held;
* ``tool_calls``: a new table. An earlier run folder has no ``tool_calls`` folder, which every
  reader already takes as a table without rows (an empty view with the full schema), so such a
  run reads as one whose episodes made no tool calls.

Also under version 5, ``evaluations`` (issue 29): a new table, one row per judged SWE-bench
submission. No version bump: a new table adds no column to an existing one, a run folder without
an ``evaluations`` folder reads as a table without rows (as above), and a version 5 run continued
by a recap that writes it only gains rows there, so every earlier reader and writer of version 5
stays right.

Also under version 5, ``episodes.end_reason`` ``autosubmitted`` (issue 34: the diff handed in and
graded at a limit). No version bump: a new value of a closed vocabulary adds no column, and no
earlier row holds it.

A run folder of version 2, 3 or 4 may be continued by this version (:func:`continues`): its
parts differ from the current ones only by ``model_name`` and the messages' tool columns (filled
on read) and the name of the sampling seed's column (renamed on read), so parts of several
versions side by side read as one table: the new parts carry ``sampling_seed``, the old ones
``seed``, and every reader sees ``sampling_seed``; new ``messages`` parts carry the tool columns,
the old ones read them as null; the continuation's ``tool_calls`` rows are its own. A version 1
run is read, never continued.

Any table, any earlier version: a missing column that has a default in its record dataclass (or
is nullable) is filled with that default (null); a part missing any other column is not readable
(the reader names it, as for any part that breaks :func:`schemas.parts.schema_problem`).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

from schemas.labels import INFRA_ERROR, ablation_of_config, infra_failure, parse_default_label, place_of
from schemas.records import SCHEMA_VERSION
from schemas.tables import arrow_schema, record_type

if TYPE_CHECKING:  # imported where a table is mapped (upgrade): see schemas/parts.py
    import pyarrow as pa

VERSION_KEY = b"recap_eval_schema_version"

#: columns each version added, by table (the first version a part may lack them before)
ADDED: dict[int, dict[str, tuple[str, ...]]] = {
    2: {"episodes": ("label", "profile", "ablation", "provider_model")},
    3: {"llm_calls": ("model_name",)},
    5: {"messages": ("tool_call_id", "tool_calls")},
}

#: columns each version renamed, by table: new name -> the name parts of earlier versions have
RENAMED: dict[int, dict[str, dict[str, str]]] = {
    4: {"episodes": {"sampling_seed": "seed"}},
}

#: earlier versions whose run folders this version continues (their parts only lack columns
#: that are filled on read, or have them under an old name, the same way whichever session
#: wrote them)
CONTINUED: frozenset[int] = frozenset({2, 3, 4})


def continues(version: int) -> bool:
    """May a run folder written under ``version`` be continued (resumed) by this version?"""
    return version == SCHEMA_VERSION or version in CONTINUED


def part_version(schema: pa.Schema) -> int | None:
    """The schema version a part was written under (None: it does not say)."""
    raw = (schema.metadata or {}).get(VERSION_KEY)
    try:
        return int(raw) if raw is not None else None
    except ValueError:
        return None


def column_defaults(table: str) -> dict[str, Any]:
    """Column -> default value of the table's record dataclass (only columns that have one)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(record_type(table)):
        if f.default is not dataclasses.MISSING:
            out[f.name] = f.default
        elif f.default_factory is not dataclasses.MISSING:
            out[f.name] = f.default_factory()
    return out


def renamed_since(table: str, version: int | None) -> dict[str, str]:
    """New column name -> the name a part of ``version`` stores it under, for the columns of
    ``table`` renamed since that version ({} for a current part or one that does not say)."""
    if version is None or version >= SCHEMA_VERSION:
        return {}
    return {new: old for v, tables in sorted(RENAMED.items()) if v > version for new, old in tables.get(table, {}).items()}


def stored_names(table: str, found: list[str], version: int | None) -> dict[str, str]:
    """Current column name -> the name it has in a part whose columns are ``found`` (written
    under ``version``), for every current column the part holds, under either name."""
    renamed = renamed_since(table, version)
    out: dict[str, str] = {}
    for name in arrow_schema(table).names:
        if name in found:
            out[name] = name
        elif renamed.get(name) in found:
            out[name] = renamed[name]
    return out


def missing_fillable(table: str, missing: list[str], version: int | None) -> bool:
    """A part of ``version`` that lacks ``missing`` columns can be read: it is of an earlier
    version and every missing column was added since, or has a default (or is nullable)."""
    if version is None or version >= SCHEMA_VERSION or not missing:
        return False
    schema = arrow_schema(table)
    defaults = column_defaults(table)
    added = {c for v, tables in ADDED.items() if v > version for c in tables.get(table, ())}
    return all(c in added or c in defaults or schema.field(c).nullable for c in missing)


def upgrade(table: str, data: pa.Table, version: int) -> pa.Table:
    """The rows of a part of ``version`` as the current schema has them (see the module doc)."""
    import pyarrow as pa

    schema = arrow_schema(table)
    renamed = {old: new for new, old in renamed_since(table, version).items() if old in data.column_names}
    if renamed:
        data = data.rename_columns([renamed.get(c, c) for c in data.column_names])
    if version < 2 and table == "episodes":
        rows = [_episode_v1(r) for r in data.to_pylist()]
        return pa.Table.from_pylist(rows, schema=schema) if rows else schema.empty_table()
    if version < 3 and table == "llm_calls" and "model_name" not in data.column_names:
        n = data.num_rows
        models = data.column("model").to_pylist() if "model" in data.column_names else [None] * n
        deployments = data.column("deployment").to_pylist() if "deployment" in data.column_names else [None] * n
        names = [model_name_v2(m, d) for m, d in zip(models, deployments)]
        data = data.append_column("model_name", pa.array(names, type=pa.string()))
    defaults = column_defaults(table)
    cols = []
    for f in schema:
        if f.name in data.column_names:
            cols.append(data.column(f.name).cast(f.type))
        else:
            cols.append(pa.array([defaults.get(f.name)] * data.num_rows, type=f.type))
    return pa.Table.from_arrays(cols, schema=schema)


def model_name_v2(model: str | None, deployment: str | None) -> str | None:
    """The sweep name of a version 2 ``llm_calls`` row's model (see the module doc)."""
    if not deployment:
        return None
    if model and (deployment == model or deployment.startswith((model + "@", model + "#"))):
        return model
    return deployment


def _episode_v1(row: dict[str, Any]) -> dict[str, Any]:
    stored = row.get("method") or ""
    out = dict(row)
    out["label"] = stored
    parsed = parse_default_label(stored)
    if parsed is not None:
        out["method"], out["profile"], ablation = parsed
        out["ablation"] = None if ablation in (None, "original") else ablation
    else:
        out["profile"] = None
        out["ablation"] = ablation_of_config(row.get("method_config"))
    out["provider_model"] = None
    if row.get("benchmark") == "alfworld" or not row.get("split"):
        _, out["split"], out["task"] = place_of(row.get("instance_id") or "", row.get("split") or None, row.get("task") or None)
    if infra_failure(row.get("end_reason"), row.get("error")) is not None:
        out["end_reason"] = INFRA_ERROR
    return out
