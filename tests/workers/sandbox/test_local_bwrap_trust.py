"""``sandbox_trust`` (issue 35 item 1): a sweep with ``sandbox: local`` where bubblewrap does not
work is refused by ``recap run`` in one line, exit 2, before any episode (or money), naming both
fixes; ``sandbox_trust: none`` lets it through; a bad value is one line too."""

from __future__ import annotations

from pathlib import Path

import pytest

from workers.envs.swe.examples import make_fixtures

SPEC = """run: trust
output: {out}
models:
  - model: offline/expert
methods:
  - method: recap
    profile: paper
environments:
  - benchmark: swe
    tasks: [all]
    options: {{instances_file: "{tasks}", sandbox: local{extra}}}
"""


def _run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], extra: str
) -> tuple[int, list[str]]:
    import pipeline.cli as cli
    import pipeline.cli.run as run_command
    from workers.sandbox import bwrap

    def never(*_a: object, **_k: object) -> None:
        raise AssertionError("the run started: the preflight did not stop it")

    monkeypatch.setattr(run_command, "_execute", never)
    monkeypatch.setattr(bwrap, "probe", lambda: "bubblewrap (bwrap) is not installed")
    fixtures = make_fixtures(tmp_path / "fx", ("format",))
    spec = tmp_path / "sweep.yaml"
    spec.write_text(SPEC.format(out=tmp_path / "out", tasks=fixtures.tasks_file, extra=extra))
    code = cli.main(["run", str(spec), "--dry-run"])
    return code, capsys.readouterr().err.strip().splitlines()


def test_local_without_bubblewrap_is_refused_before_the_run(tmp_path, monkeypatch, capsys) -> None:
    code, err = _run(tmp_path, monkeypatch, capsys, "")
    assert code == 2 and len(err) == 1
    assert err[0].startswith("recap: error: ")
    assert (
        "bubblewrap (bwrap) is not installed: install it (apt-get install bubblewrap) or set the swe option sandbox_trust: none"
        in err[0]
    )
    assert not (tmp_path / "out").exists()


def test_sandbox_trust_none_lets_it_through(tmp_path, monkeypatch, capsys) -> None:
    code, err = _run(tmp_path, monkeypatch, capsys, ", sandbox_trust: none")
    assert code == 0, err


def test_a_bad_sandbox_trust_is_one_line(tmp_path, monkeypatch, capsys) -> None:
    code, err = _run(tmp_path, monkeypatch, capsys, ", sandbox_trust: maybe")
    assert code == 2 and len(err) == 1
    assert "sandbox_trust must be 'isolated' (a local sandbox confines commands with bubblewrap) or 'none'" in err[0]
    assert err[0].endswith("got 'maybe'")
