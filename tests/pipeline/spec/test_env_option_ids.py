"""Environment options in the unit id (issue 36 item 1): a benchmark declares which of its options
change what an episode does (in the id) and which only how it is run (not); an undeclared
option is refused before anything runs; a run whose episode options changed re-plans those
units as ``changed``; runs written before options were hashed keep their units."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pipeline.cli import main as cli_main
from pipeline.errors import SpecError
from pipeline.prepare import prepare
from pipeline.spec import parse_spec
from pipeline.store import PLAN_FILE, SPEC_FILE, RunStore
from pipeline.units import expand, unit_hash
from workers.envs.options import EPISODE, RUN, episode, identity_options, run
from workers.envs.registry import benchmark_names, get_benchmark, registered_benchmark
from workers.envs.swe.examples import make_fixtures

SWE = """run: ids
output: {out}
models:
  - model: offline/expert
methods:
  - method: recap
    profile: paper
environments:
  - benchmark: swe
    tasks: [all]
    options: {{instances_file: "{tasks}"{extra}}}
"""

FEVER = """run: ids
output: {out}
models:
  - model: offline/expert
methods:
  - method: react
environments:
  - benchmark: fever
    tasks: [all]
    limit: 2
    options: {{data_dir: "{claims}"{extra}}}
"""


@pytest.fixture(scope="module")
def tasks(tmp_path_factory) -> str:
    return str(make_fixtures(tmp_path_factory.mktemp("fx"), ("offbyone", "format")).tasks_file)


@pytest.fixture
def claims(tmp_path) -> str:
    folder = tmp_path / "claims"
    folder.mkdir()
    rows = [
        {"id": 1, "label": "SUPPORTS", "claim": "A is B.", "evidence": []},
        {"id": 2, "label": "REFUTES", "claim": "C is D.", "evidence": []},
    ]
    (folder / "paper_dev.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    return str(folder)


def _planned(out: Path, text: str) -> str:
    """Plan ``text`` against the run folder ``out``, then leave the folder as a session leaves it
    (run.json, spec.yaml, plan.json); returns the plan line ("2 new, 0 unchanged, 0 changed")."""
    spec = parse_spec(text, "sweep.yaml")
    p = prepare(spec, text, check_keys=False)
    store = RunStore(str(out))
    if p.identity is None:
        store.create_identity(spec.run)
    store.write_text(SPEC_FILE, text)
    store.write_text(PLAN_FILE, p.plan.to_json() + "\n")
    return p.diff.describe() if p.diff is not None else f"{len(p.plan.units)} new"


def _swe(out: Path, tasks: str, extra: str = "") -> str:
    return SWE.format(out=out, tasks=tasks, extra=extra)


def test_a_swe_sweep_switched_to_docker_with_another_command_timeout_replans_its_units_as_changed(tmp_path, tasks):
    out = tmp_path / "run"
    assert _planned(out, _swe(out, tasks, ", sandbox: local, command_timeout_s: 30")) == "2 new"
    assert _planned(out, _swe(out, tasks, ", sandbox: local, command_timeout_s: 30")) == "0 new, 2 unchanged, 0 changed"
    # the sweep: local -> docker and another command_timeout_s re-ran nothing; now both units change
    assert _planned(out, _swe(out, tasks, ", sandbox: docker, command_timeout_s: 60")) == "0 new, 0 unchanged, 2 changed"
    # docker and 60 s are the defaults: spelled out or left out, the same units
    assert _planned(out, _swe(out, tasks)) == "0 new, 2 unchanged, 0 changed"
    for change in (", grading: ours", ", max_commands: 7", ", image: other:tag", ", eval_timeout_s: 9", ", network: true"):
        assert _planned(out, _swe(out, tasks, change)) == "0 new, 0 unchanged, 2 changed", change
        assert _planned(out, _swe(out, tasks)) == "0 new, 0 unchanged, 2 changed", change
    # how it is run: where the records are read from, the permission to run unconfined
    copy = Path(tasks).with_name("copy.jsonl")  # beside it: its repo_paths are relative
    copy.write_text(Path(tasks).read_text())
    assert _planned(out, SWE.format(out=out, tasks=copy, extra=", sandbox_trust: none")) == "0 new, 2 unchanged, 0 changed"


def test_fever_wikipedia_source_and_step_cap_are_in_the_id_its_rate_and_sample_are_not(tmp_path, claims):
    out = tmp_path / "run"

    def fever(extra: str = "") -> str:
        return FEVER.format(out=out, claims=claims, extra=extra)

    assert _planned(out, fever()) == "2 new"
    assert _planned(out, fever(', wikipedia: "snapshot:/runs/old"')) == "0 new, 0 unchanged, 2 changed"
    assert _planned(out, fever(', wikipedia_url: "http://127.0.0.1:9"')) == "0 new, 0 unchanged, 2 changed"
    assert _planned(out, fever(', wikipedia_url: "https://en.wikipedia.org", max_steps: 4')) == "0 new, 0 unchanged, 2 changed"
    assert _planned(out, fever(', wikipedia_url: "https://en.wikipedia.org"')) == "0 new, 0 unchanged, 2 changed"
    run_only = ", wikipedia_rate: 0.5, wikipedia_deadline_s: 5, wikipedia_max_page_bytes: 1000, sample_seed: 7"
    assert _planned(out, fever(run_only)) == "0 new, 2 unchanged, 0 changed"


def test_an_undeclared_option_is_refused_in_one_line_before_anything_runs(tmp_path, tasks, capsys):
    text = _swe(tmp_path / "run", tasks, ", comand_timeout_s: 30")
    with pytest.raises(SpecError) as err:
        expand(parse_spec(text, "sweep.yaml"))
    assert str(err.value) == (
        "environments[0]: unknown swe option(s) comand_timeout_s; what an episode does: command_timeout_s, eval_timeout_s, "
        "grading, image, max_commands, max_timeouts_in_row, network, output_bytes, sandbox, total_output_bytes, "
        "wall_time_s; how it is run: instances_file, sandbox_trust"
    )
    # the command line: exit 2, one line, nothing written
    sweep = tmp_path / "sweep.yaml"
    sweep.write_text(text)
    assert cli_main(["run", str(sweep), "--dry-run"]) == 2
    err_lines = capsys.readouterr().err.strip().splitlines()
    assert len(err_lines) == 1 and "unknown swe option(s) comand_timeout_s" in err_lines[0]
    assert not (tmp_path / "run").exists()
    # blocksworld takes no option (it used to ignore any silently); the sweep-level key is named
    bw = "run: b\noutput: o\nmodels: [{model: offline/expert}]\nmethods: [{method: react}]\n"
    bw += "environments: [{benchmark: blocksworld, tasks: ['3'], options: {step_multiplier: 2}}]\n"
    with pytest.raises(SpecError, match=r"^environments\[0\]: blocksworld declares no options, got step_multiplier "):
        expand(parse_spec(bw, "sweep.yaml"))


def test_every_builtin_benchmark_declares_each_option_its_make_accepts_with_a_kind():
    kinds = {name: {k: o.kind for k, o in get_benchmark(name).declared_options().items()} for name in benchmark_names()}
    assert kinds == {
        "blocksworld": {},
        "robotouille": {"data_dir": RUN, "engine": EPISODE},
        "alfworld": {
            "data_dir": RUN,
            "data_dir_2_1_2": RUN,
            "version": EPISODE,
            "max_steps": EPISODE,
            "show_valid_actions": EPISODE,
            "demo_valid_actions": EPISODE,
        },
        "fever": {
            "data_dir": RUN,
            "wikipedia_url": EPISODE,
            "wikipedia": EPISODE,
            "wikipedia_rate": RUN,
            "wikipedia_deadline_s": RUN,
            "wikipedia_max_page_bytes": RUN,
            "max_steps": EPISODE,
            "verdict_only": EPISODE,
            "sample_seed": RUN,
        },
        "swe": {
            "instances_file": RUN,
            "sandbox": EPISODE,
            "sandbox_trust": RUN,
            "image": EPISODE,
            "network": EPISODE,
            "command_timeout_s": EPISODE,
            "output_bytes": EPISODE,
            "max_commands": EPISODE,
            "wall_time_s": EPISODE,
            "total_output_bytes": EPISODE,
            "max_timeouts_in_row": EPISODE,
            "eval_timeout_s": EPISODE,
            "grading": EPISODE,
        },
        "swe-verified": {
            "data_dir": RUN,
            "sandbox": EPISODE,
            "network": EPISODE,
            "command_timeout_s": EPISODE,
            "output_bytes": EPISODE,
            "max_commands": EPISODE,
            "wall_time_s": EPISODE,
            "disk_bytes": EPISODE,
            "total_output_bytes": EPISODE,
            "max_timeouts_in_row": EPISODE,
            "eval_timeout_s": EPISODE,
            "grading": EPISODE,
            "container": EPISODE,
            "release_image": EPISODE,
            "repo_mirror": RUN,
        },
    }
    # a declared option make() does not take would be refused by every episode
    from workers.envs.swe.benchmark import ACCEPTED as SWE_ACCEPTED
    from workers.envs.swe_verified.benchmark import ACCEPTED as VERIFIED_ACCEPTED

    assert set(kinds["swe"]) <= set(SWE_ACCEPTED) and set(kinds["swe-verified"]) <= set(VERIFIED_ACCEPTED)


def test_only_episode_options_away_from_their_default_are_in_the_id():
    declared = {"grading": episode("both"), "timeout": episode(60), "flag": episode(False), "show": episode(), "rate": run()}
    assert identity_options(declared, {"grading": "both", "timeout": 60.0, "flag": False, "rate": 3}) == {}
    assert identity_options(declared, {"timeout": 60.5, "flag": 0, "show": False, "rate": 3}) == {
        "flag": 0,
        "show": False,
        "timeout": 60.5,
    }
    # a unit without options in its id keeps the id it always had (the pinned hash)
    base = dict(instance_id="blocksworld/3@1", method="recap", method_config='{"window": 64}', model="offline/expert")
    common = dict(params={}, sampling_seed=0, step_multiplier=4.0)
    assert unit_hash(**base, **common) == unit_hash(**base, **common, env_options={}) == "58de48ed5ccdeed2"
    assert unit_hash(**base, **common, env_options={"engine": "real"}) != "58de48ed5ccdeed2"


def test_a_third_party_benchmark_declares_its_options_and_one_that_declares_none_takes_none(tmp_path):
    from recap.blocksworld import BENCHMARK as PURE
    from workers.envs.registry import Benchmark

    class Tower(Benchmark):
        name = "tower"

        def list_instances(self, selector=None):
            return ["tower/1"]

        def make(self, instance_id, **options):
            return PURE.make("blocksworld/3@1")

    class TowerWithOptions(Tower):
        def declared_options(self):
            return {"height": episode(3), "cache": run()}

    text = (
        "run: t\noutput: o\nmodels: [{model: offline/expert}]\nmethods: [{method: react}]\n"
        "environments: [{benchmark: tower, tasks: [all], options: {OPTIONS}}]\n"
    )
    with registered_benchmark("tower", Tower()):
        assert len(expand(parse_spec(text.replace("{OPTIONS}", "{}"), "s")).units) == 1
        with pytest.raises(SpecError) as err:
            expand(parse_spec(text.replace("{OPTIONS}", "{height: 4}"), "s"))
        assert str(err.value) == (
            "environments[0]: tower declares no options, got height (a benchmark declares them with Benchmark.declared_options)"
        )
    with registered_benchmark("tower", TowerWithOptions()):

        def uid(options: str) -> str:
            return expand(parse_spec(text.replace("{OPTIONS}", options), "s")).units[0].unit_id

        assert uid("{}") == uid("{height: 3}") == uid("{cache: /x}")
        assert uid("{height: 4}") != uid("{}")


# --------------------------------------------------------------------------------------------
# runs written before options were in the unit id
# --------------------------------------------------------------------------------------------
def _as_written_before(out: Path) -> None:
    """Make the run folder's plan.json what recap wrote before options were hashed: every unit's
    id the plain one, no ``env_options``."""
    from pipeline.units import unit_hash as h

    store = RunStore(str(out))
    plan = json.loads(store.read_text(PLAN_FILE) or "")
    spec = parse_spec(store.read_text(SPEC_FILE) or "", "spec.yaml")
    by_key = {u.key: u for u in expand(spec).units}
    for row in plan["units"]:
        u = by_key[row["key"]]
        row["unit_id"] = h(
            instance_id=u.instance_id,
            method=u.method,
            method_config=u.method_config,
            model=u.model,
            params=dict(u.model_params),
            sampling_seed=u.sampling_seed,
            step_multiplier=u.step_multiplier,
        )
        del row["env_options"]
    store.write_text(PLAN_FILE, json.dumps(plan))


def test_a_run_written_before_options_were_hashed_keeps_its_units_while_its_options_stay(tmp_path, tasks):
    out = tmp_path / "run"
    old = _swe(out, tasks, ", sandbox: local, max_commands: 40")
    _planned(out, old)
    _as_written_before(out)
    plain = {u["key"]: u["unit_id"] for u in json.loads(RunStore(str(out)).read_text(PLAN_FILE) or "")["units"]}
    # the same options: the same units, under the ids its episodes have
    p = prepare(parse_spec(old, "sweep.yaml"), old, check_keys=False)
    assert p.diff is not None and p.diff.describe() == "0 new, 2 unchanged, 0 changed"
    assert {u.key: u.unit_id for u in p.plan.units} == plain
    # written so, a later session still keeps them, and still sees a change
    RunStore(str(out)).write_text(PLAN_FILE, p.plan.to_json())
    assert _planned(out, old) == "0 new, 2 unchanged, 0 changed"
    assert _planned(out, _swe(out, tasks, ", sandbox: local, max_commands: 41")) == "0 new, 0 unchanged, 2 changed"


def test_an_old_run_whose_options_changed_replans_as_changed_and_one_whose_options_went_is_refused(tmp_path, tasks):
    out = tmp_path / "run"
    _planned(out, _swe(out, tasks, ", sandbox: local"))
    _as_written_before(out)
    assert _planned(out, _swe(out, tasks, ", sandbox: local, grading: ours")) == "0 new, 0 unchanged, 2 changed"

    out2 = tmp_path / "run2"
    _planned(out2, _swe(out2, tasks, ", sandbox: local"))
    _as_written_before(out2)
    text = _swe(out2, tasks)
    with pytest.raises(SpecError) as err:
        prepare(parse_spec(text, "sweep.yaml"), text, check_keys=False)
    assert str(err.value).startswith(
        "2 unit(s) of this run ran with environment options it no longer sets (first: swe/"
    ) and "(sandbox: local)" in str(err.value)


def test_an_old_run_whose_spec_gave_an_option_refused_now_keeps_its_units_once_the_option_is_dropped(tmp_path, tasks):
    """``seed`` had no effect on swe and is refused now: the stored spec.yaml that still has it
    says what the units ran with all the same."""
    out = tmp_path / "run"
    text = _swe(out, tasks, ", sandbox: local")
    _planned(out, text)
    _as_written_before(out)
    store = RunStore(str(out))
    store.write_text(SPEC_FILE, text.replace("sandbox: local", "sandbox: local, seed: 3"))
    p = prepare(parse_spec(text, "sweep.yaml"), text, check_keys=False)
    assert p.diff is not None and p.diff.describe() == "0 new, 2 unchanged, 0 changed"
    assert all(u.earlier_id for u in p.plan.units)
