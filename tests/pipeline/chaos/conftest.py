"""Fixtures of the chaos suite: one lab (shared Ray, fake servers, folders) per module."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.pipeline.chaos.harness import Lab


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Lab]:
    lab = Lab(tmp_path_factory.mktemp("chaos"), seed=0)
    yield lab
    lab.close()
