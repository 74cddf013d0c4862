"""Every example sweep file parses with the current spec and uses no old key name (issue 36 item 11:
``examples/paper/main-fever.yaml`` still said ``seeds:``, the old name of ``sampling_seeds``). An
example is what a new user copies: it must show the names the documentation uses."""

from __future__ import annotations

import typing
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml
from pydantic import AliasChoices, BaseModel

from pipeline.spec import SweepSpec, load_spec

REPO = Path(__file__).resolve().parents[3]
#: every sweep file of examples/ (the Ray cluster launcher files beside them, cluster*.yaml, are not sweeps)
EXAMPLES = sorted(p for p in (REPO / "examples").rglob("*.yaml") if not p.name.startswith("cluster"))


def _models(annotation: Any) -> Iterator[type[BaseModel]]:
    """The pydantic models an annotation holds (``X``, ``list[X]``, ``X | None``, ``Annotated[X, ...]``)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        yield annotation
    for arg in typing.get_args(annotation):
        yield from _models(arg)


def old_keys(model: type[BaseModel], data: Any, where: str = "") -> Iterator[str]:
    """Where ``data`` (read into ``model``) uses a field's old name: a validation alias other than the field's own name."""
    if not isinstance(data, dict):
        return
    for name, field in model.model_fields.items():
        alias = field.validation_alias
        old = [c for c in alias.choices if isinstance(c, str) and c != name] if isinstance(alias, AliasChoices) else []
        for key in old:
            if key in data:
                yield f"{where}{key} (now {name})"
        value = data.get(name)
        for sub in _models(field.annotation):
            items = value if isinstance(value, list) else [value]
            for i, item in enumerate(items):
                yield from old_keys(sub, item, f"{where}{name}{f'[{i}]' if isinstance(value, list) else ''}.")


def test_the_check_finds_an_old_key():
    assert list(old_keys(SweepSpec, {"run": "x", "seeds": [0]})) == ["seeds (now sampling_seeds)"]


@pytest.mark.parametrize("path", EXAMPLES, ids=[str(p.relative_to(REPO / "examples")) for p in EXAMPLES])
def test_every_example_parses_with_current_key_names(path: Path):
    spec, text = load_spec(path)
    assert isinstance(spec, SweepSpec)
    assert list(old_keys(SweepSpec, yaml.safe_load(text))) == []
