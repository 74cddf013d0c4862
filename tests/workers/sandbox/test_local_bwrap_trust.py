"""``sandbox_trust`` (issue 35 item 1): a sweep with ``sandbox: local`` where bubblewrap does not
work is refused by ``recap run`` in one line, exit 2, before any episode (or money), naming both
fixes; ``sandbox_trust: none`` lets it through; a bad value is one line too."""

from __future__ import annotations

from pathlib import Path

import pytest

from workers.envs.swe.examples import make_fixtures
from workers.sandbox import local_sandbox

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
    monkeypatch.setattr(local_sandbox, "DEFAULT_TRUST", "isolated")  # as a sweep has it (RECAP_SKIP_BWRAP aside)
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


def test_the_sweeps_trust_reaches_the_episodes_sandbox(tmp_path, monkeypatch) -> None:
    """make() -> the environment -> its sandbox at reset: under ``none`` without bubblewrap the
    episode's sandbox is the unconfined fallback, and says so; the default refuses at make()."""
    from workers.envs.swe.benchmark import BENCHMARK
    from workers.sandbox import SandboxError, bwrap
    from workers.sandbox.local_sandbox import WARNING

    monkeypatch.setattr(bwrap, "probe", lambda: "bubblewrap (bwrap) is not installed")
    monkeypatch.setattr(local_sandbox, "DEFAULT_TRUST", "isolated")
    fixtures = make_fixtures(tmp_path / "fx", ("format",))
    options = {"instances_file": str(fixtures.tasks_file), "sandbox": "local"}
    (iid,) = BENCHMARK.list_instances_for("all", options)
    with pytest.raises(SandboxError, match="sandbox_trust: none"):
        BENCHMARK.make(iid, **options)
    env = BENCHMARK.make(iid, **options, sandbox_trust="none")
    try:
        env.reset()
        box = env._sandbox  # type: ignore[attr-defined]
        assert box.warning == WARNING and box.trust == "none" and "bwrap" not in box.confinement
    finally:
        env.close()
