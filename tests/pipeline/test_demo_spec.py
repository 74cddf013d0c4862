"""The demo's sweep follows the data the machine has: a benchmark without data is left out with
a line saying how to fetch it; with none, blocksworld stands in."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("demo_spec", REPO / "scripts" / "demo_spec.py")
demo_spec = importlib.util.module_from_spec(spec)
spec.loader.exec_module(demo_spec)


def test_the_demo_keeps_what_it_can_run(tmp_path, monkeypatch, capsys):
    out = tmp_path / "demo.yaml"
    assert demo_spec.main(str(REPO / "examples" / "demo.yaml"), str(out)) == 0
    assert [e["benchmark"] for e in yaml.safe_load(out.read_text())["environments"]] == ["robotouille", "alfworld"]
    assert capsys.readouterr().out == ""
    monkeypatch.setenv("ALFWORLD_DATA", str(tmp_path / "none"))
    assert demo_spec.main(str(REPO / "examples" / "demo.yaml"), str(out)) == 0
    assert [e["benchmark"] for e in yaml.safe_load(out.read_text())["environments"]] == ["robotouille"]
    line = capsys.readouterr().out.strip()
    assert line.startswith("demo: alfworld left out (") and line.endswith("get it with: .venv/bin/recap data fetch alfworld")
    monkeypatch.setenv("ROBOTOUILLE_DATA", str(tmp_path / "none"))
    assert demo_spec.main(str(REPO / "examples" / "demo.yaml"), str(out)) == 0
    assert yaml.safe_load(out.read_text())["environments"] == [{"benchmark": "blocksworld", "tasks": ["3"], "limit": 2}]
    assert (
        capsys.readouterr().out.strip().splitlines()[-1]
        == "demo: no benchmark data found; running the built-in blocksworld instead"
    )
