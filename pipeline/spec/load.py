"""From sweep-file text to a validated :class:`~pipeline.spec.schema.SweepSpec`, each problem one line.

The reader (:mod:`pipeline.spec.safe_yaml`) refuses what YAML may not carry; the schema
(:mod:`pipeline.spec.schema`) what the fields may not hold; here pydantic's errors become the one
``SpecError`` line a user sees (``sweep.yaml: models[0].rpm: ...``).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from pydantic import ValidationError

from pipeline.errors import SpecError
from pipeline.spec.fields import field_path
from pipeline.spec.safe_yaml import load_yaml, read_spec_text
from pipeline.spec.schema import SweepSpec


def _pydantic_message(source: str, exc: ValidationError) -> str:
    errors = exc.errors()
    first = errors[0]
    loc = field_path(tuple(x for x in first.get("loc", ()) if not str(x).startswith("function-")))
    msg = first.get("msg", "invalid")
    if first.get("type") == "extra_forbidden":
        msg = "unknown field"
    elif first.get("type") == "missing":
        msg = "required field is missing"
    msg = msg.removeprefix("Value error, ")
    more = f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})" if len(errors) > 1 else ""
    return f"{source}: {loc + ': ' if loc else ''}{msg}{more}"


def parse_spec(text: str, source: str = "spec") -> SweepSpec:
    """Parse and validate YAML text; every problem is one :class:`SpecError` line."""
    data = load_yaml(text, source)
    if not isinstance(data, dict):
        raise SpecError(f"{source}: the sweep file must be a YAML mapping (run:, output:, models:, ...)")
    try:
        return SweepSpec.model_validate(data)
    except ValidationError as exc:
        raise SpecError(_pydantic_message(source, exc)) from None


def load_spec(path: str | Path) -> tuple[SweepSpec, str]:
    """(validated spec, its YAML text) from a file."""
    text = read_spec_text(path)
    return parse_spec(text, Path(path).name), text


def with_overrides(spec: SweepSpec, **changes: object) -> SweepSpec:
    """A copy with top-level fields replaced (CLI flags such as --workers, --run-cap)."""
    changes = {k: v for k, v in changes.items() if v is not None}
    if not changes:
        return spec
    data = spec.model_dump()
    ray_changes = {k: changes.pop(k) for k in ("address",) if k in changes}
    data.update(changes)
    data["ray"].update(ray_changes)
    try:
        return SweepSpec.model_validate(data)
    except ValidationError as exc:
        raise SpecError(_pydantic_message("command line", exc)) from None


def text_hash(text: str) -> str:
    """A short content hash of ``text`` (the first 16 hex digits of its sha256), e.g. the
    ``spec_hash`` of the sweep file a run records."""
    return hashlib.sha256(text.encode()).hexdigest()[:16]
