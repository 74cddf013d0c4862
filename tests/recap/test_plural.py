"""Counts in words (issue 36 item 13: "1 files checked", "1 episodes")."""

from __future__ import annotations

import pytest

from recap.plural import count, plural


@pytest.mark.parametrize(
    "n, noun, text",
    [
        (1, "file", "1 file"),
        (0, "file", "0 files"),
        (2, "episode", "2 episodes"),
        (1, "instance image", "1 instance image"),
        (3, "instance image", "3 instance images"),
        (2, "match", "2 matches"),
        (2, "query", "2 queries"),
        (2, "day", "2 days"),
        (2, "child", "2 children"),
    ],
)
def test_count(n, noun, text):
    assert count(n, noun, "children" if noun == "child" else None) == text


def test_plural_of_one_is_the_noun():
    assert plural(1, "files") == "files" and plural(1.0, "unit") == "unit"


def test_data_check_line_says_1_file(tmp_path):
    from pipeline.data import CheckResult
    from workers.envs.registry import data_folders

    bench = next(iter(data_folders().values()))
    line = CheckResult(bench, tmp_path, checked=1).line()
    assert ": 1 file checked: " in line, line
