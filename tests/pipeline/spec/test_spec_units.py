"""Sweep specs, unit hashes, plan diffs and the run folder's identity (no Ray)."""

from __future__ import annotations

import json

import pytest

from pipeline.errors import RunFolderError, SpecError
from pipeline.spec import parse_spec, with_overrides
from pipeline.store import RunStore
from pipeline.units import diff_plans, expand, unit_hash

BASE = """
run: unit-test
output: {out}
models:
  - model: offline/expert
methods:
  - method: recap
environments:
  - benchmark: blocksworld
    tasks: ["3"]
seeds: [0, 1]
"""


def spec_of(text: str, out: str = "/tmp/never-written"):
    return parse_spec(text.replace("{out}", out), "sweep.yaml")


def test_defaults_and_unit_count():
    spec = spec_of(BASE)
    assert (spec.workers, spec.max_attempts, spec.step_multiplier, spec.run_cap_usd) == (4, 3, 4.0, None)
    plan = expand(spec)
    # 3 blocksworld instances of size 3 x 1 method x 1 model x 2 seeds
    assert len(plan.units) == 6
    assert [u.instance_id for u in plan.units[:2]] == ["blocksworld/3@1", "blocksworld/3@1"]
    assert [u.sampling_seed for u in plan.units[:2]] == [0, 1]
    assert len({u.unit_id for u in plan.units}) == 6
    assert plan.units[0].key == "blocksworld/3@1 | recap | offline/expert | seed 0"


def test_sampling_seeds_and_their_old_name_seeds_make_the_same_units():
    old = expand(spec_of(BASE))
    new_spec = spec_of(BASE.replace("seeds: [0, 1]", "sampling_seeds: [0, 1]"))
    assert new_spec.sampling_seeds == [0, 1]
    new = expand(new_spec)
    assert [(u.unit_id, u.key) for u in new.units] == [(u.unit_id, u.key) for u in old.units]
    # the unit ids of runs written before the rename (the hash keeps the name "seed")
    assert old.units[0].unit_id == unit_hash(
        instance_id="blocksworld/3@1",
        method="recap",
        method_config=old.units[0].method_config,
        model="offline/expert",
        params={},
        sampling_seed=0,
        step_multiplier=4.0,
    )
    # an error names the key the file used
    with pytest.raises(SpecError, match=r"^sweep.yaml: sampling_seeds: repeated seed$"):
        spec_of(BASE.replace("seeds: [0, 1]", "sampling_seeds: [1, 1]"))


def test_the_noise_seed_option_and_its_old_name_seed_make_the_same_units():
    def units(options: str):
        text = BASE.replace("- model: offline/expert", f"- model: offline/expert\n    options: {options}")
        return [u.unit_id for u in expand(spec_of(text)).units]

    assert units("{noise_seed: 3, invalid_action_rate: 0.1}") == units("{seed: 3, invalid_action_rate: 0.1}")
    assert units("{noise_seed: 3}") != units("{noise_seed: 4}")


@pytest.mark.parametrize(
    "text, message",
    [
        (
            "run: x\noutput: o\nmodels:\n  - model: a\n   bad",
            "sweep.yaml: malformed YAML at line 5, column 4: expected <block end>, but found '<scalar>'",
        ),
        ("- a", "sweep.yaml: the sweep file must be a YAML mapping (run:, output:, models:, ...)"),
        (
            BASE.replace("- model: offline/expert", "- model: offline/expert\n    rmp: 3"),
            "sweep.yaml: models[0].rmp: unknown field",
        ),
        (
            BASE.replace("- model: offline/expert", "- model: offline/expert\n    prices: {input: -1, output: 2}"),
            "sweep.yaml: models[0].prices.input: -1 is out of range [0, 10000]",
        ),
        (
            BASE.replace("run: unit-test", "run: 'bad name'"),
            "sweep.yaml: run: must be letters, digits, '.', '_' or '-' (starting with a letter or digit)",
        ),
        (BASE.replace("seeds: [0, 1]", "seeds: [0, 0]"), "sweep.yaml: seeds: repeated seed"),
        (
            BASE.replace("seeds: [0, 1]", "seeds: [0, 1]\nsampling_seeds: [0, 1]"),
            "sweep.yaml: give sampling_seeds or its old name seeds, not both",
        ),
        (
            BASE.replace("seeds: [0, 1]", "sampling_seeds: [-1]"),
            "sweep.yaml: sampling_seeds[0]: -1 is out of range [0, 2147483647]",
        ),
        (BASE.replace("run: unit-test\n", ""), "sweep.yaml: run: required field is missing"),
        (
            BASE.replace("  - method: recap\n", "  - method: recap\n  - method: recap\n"),
            "sweep.yaml: methods: two entries are both named 'recap'; give them distinct 'label's",
        ),
    ],
)
def test_spec_errors_are_one_line(text, message):
    with pytest.raises(SpecError) as err:
        spec_of(text)
    assert str(err.value) == message


@pytest.mark.parametrize(
    "change, message",
    [
        (
            ("benchmark: blocksworld", "benchmark: nowhere"),
            "environments[0]: unknown benchmark 'nowhere'; known: blocksworld, robotouille, alfworld, fever, swe, swe-verified",
        ),
        (
            ('tasks: ["3"]', 'tasks: ["9"]'),
            "environments[0]: blocksworld task '9': no blocksworld instance matches '9'; sizes [3, 4, 5], e.g. blocksworld/3@1",
        ),
        (
            ("- method: recap", "- method: recap\n    settings: {windw: 3}"),
            "methods[0] (recap): unknown setting(s) windw for ReCAPConfig; known: action_pattern, context_drop, "
            "context_overflow, demo_observations, final_answer, json_mode, max_episode_cost_usd, max_episode_tokens, "
            "max_json_repairs, max_level, max_llm_calls, max_tokens, name_only, observation_drop, pin_task, reminder_on, "
            "reminder_period, reply_schema, resend_bad_replies, safety_steps, shortcut, shortcut_trace, submit_at_limit, temperature, "
            "think, tool_calls_per_reply, valid_actions, window, window_block, window_counts_pins, window_mode",
        ),
        (
            ("- method: recap", "- method: recap\n    ablation: level_9"),
            "methods[0] (recap[level_9]): unknown ablation 'level_9'; known: original, no_think, think_many, name_only, level_2, level_3, level_4, level_5, no_shortcut",
        ),
    ],
)
def test_expansion_errors_name_the_entry(change, message):
    with pytest.raises(SpecError) as err:
        expand(spec_of(BASE.replace(*change)))
    assert str(err.value) == message


def test_unit_hash_is_pinned():
    """The hash of a fixed unit must never change silently (finished work would re-run)."""
    uid = unit_hash(
        instance_id="blocksworld/3@1",
        method="recap",
        method_config='{"window": 64}',
        model="offline/expert",
        params={},
        sampling_seed=0,
        step_multiplier=4.0,
    )
    assert uid == "58de48ed5ccdeed2"


def test_transport_settings_do_not_change_unit_ids():
    ids = [u.unit_id for u in expand(spec_of(BASE)).units]
    transport = (
        BASE.replace(
            "- model: offline/expert",
            "- model: offline/expert\n    rpm: 10\n    tpm: 1000\n    concurrency: 2\n"
            "    retries: 9\n    timeout_s: 5\n    api_base: http://127.0.0.1:1\n    cap_usd: 3\n"
            "    prices: {input: 1, output: 1, cached_input: 0.1, cache_write: 1.25}",
        )
        + "workers: 16\nmax_attempts: 5\nrun_cap_usd: 2\n"
    )
    assert [u.unit_id for u in expand(spec_of(transport)).units] == ids
    assert [u.unit_id for u in expand(with_overrides(spec_of(BASE), workers=9, run_cap_usd=1.5)).units] == ids


def test_a_price_override_carries_the_cache_write_price():
    from workers.llm.pricing import resolve_price

    spec = spec_of(
        BASE.replace(
            "- model: offline/expert",
            "- model: offline/expert\n    prices: {input: 3, output: 15, cached_input: 0.3, cache_write: 3.75}",
        )
    )
    price = resolve_price("offline/expert", spec.models[0].prices.model_dump())
    # 1,000 prompt tokens: 200 read from the cache, 300 written to it, 500 plain; 100 output tokens
    assert price.cost_usd(1000, 200, 100, 300) == pytest.approx((500 * 3 + 200 * 0.3 + 300 * 3.75 + 100 * 15) / 1e6, abs=1e-12)


@pytest.mark.parametrize(
    "change",
    [
        ("- method: recap", "- method: recap\n    settings: {window: 32}"),
        ("- method: recap", "- method: recap\n    label: recap\n    ablation: no_think"),
        ("- model: offline/expert", "- model: offline/expert\n    params: {max_tokens: 256}"),
        ("- model: offline/expert", "- model: offline/expert\n    options: {invalid_action_rate: 0.2}"),
        ("seeds: [0, 1]", "seeds: [0, 1]\nstep_multiplier: 2"),
        ("seeds: [0, 1]", "seeds: [0, 1]\nlimits: {llm_calls: 50}"),
    ],
)
def test_content_changes_change_unit_ids(change):
    before = {u.key: u.unit_id for u in expand(spec_of(BASE)).units}
    after = {u.key: u.unit_id for u in expand(spec_of(BASE.replace(*change))).units}
    assert before.keys() == after.keys()
    assert all(before[k] != after[k] for k in before)


def test_limits_map_to_agent_config():
    spec = spec_of(BASE + "limits: {llm_calls: 50, tokens: 90000, usd: 0.5}\n")
    cfg = json.loads(expand(spec).units[0].method_config)
    assert (cfg["max_llm_calls"], cfg["max_episode_tokens"], cfg["max_episode_cost_usd"]) == (50, 90000, 0.5)
    own = spec_of(
        BASE.replace("- method: recap", "- method: recap\n    settings: {max_llm_calls: 7}") + "limits: {llm_calls: 50}\n"
    )
    assert json.loads(expand(own).units[0].method_config)["max_llm_calls"] == 7


def test_plan_diff_new_unchanged_changed():
    old = json.loads(expand(spec_of(BASE)).to_json())
    changed = BASE.replace("- method: recap", "- method: recap\n  - method: react").replace(
        'tasks: ["3"]', 'tasks: ["3"]\n    instances: [blocksworld/4@1]'
    )
    plan = expand(spec_of(changed))
    d = diff_plans(old, plan)
    assert (len(d.new), len(d.unchanged), len(d.changed), len(d.removed)) == (10, 6, 0, 0)
    assert d.describe() == "10 new, 6 unchanged, 0 changed"
    d2 = diff_plans(old, expand(spec_of(BASE.replace("- method: recap", "- method: recap\n    settings: {window: 32}"))))
    assert (len(d2.new), len(d2.unchanged), len(d2.changed)) == (0, 0, 6)
    assert d2.changed[0] == "blocksworld/3@1 | recap | offline/expert | seed 0"


def test_run_folder_identity(tmp_path):
    store = RunStore(tmp_path / "run")
    assert store.check_can_hold("a") is None
    assert not (tmp_path / "run").exists()  # checking writes nothing
    ident = store.create_identity("a")
    assert store.check_can_hold("a") == ident
    with pytest.raises(RunFolderError) as err:
        store.check_can_hold("b")
    assert str(err.value) == (
        f"output folder {tmp_path / 'run'} holds run 'a' (run_id {ident.run_id}), not 'b'; "
        "choose another output folder or use the same run name"
    )
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("mine")
    with pytest.raises(RunFolderError) as err:
        RunStore(tmp_path / "other").check_can_hold("a")
    assert str(err.value) == f"output folder {tmp_path / 'other'} is not empty and holds no run.json; choose a new folder"


def test_profiles_resolve_per_benchmark_in_the_unit_config(monkeypatch):
    """The paper profile runs Robotouille's ReAct on Robotouille and Yao et al.'s elsewhere; the
    unit's resolved config (part of its hash) says which."""
    import os

    monkeypatch.setenv(
        "ROBOTOUILLE_DATA", os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared", "data", "robotouille")
    )
    text = BASE.replace("- method: recap", "- method: react\n    profile: paper").replace(
        '    tasks: ["3"]', '    tasks: ["3"]\n    limit: 1\n  - benchmark: robotouille\n    tasks: [synchronous/0]\n    limit: 1'
    )
    plan = expand(spec_of(text))
    cfg = {u.instance_id.split("/")[0]: json.loads(u.method_config) for u in plan.units}
    rob, bw = cfg["robotouille"], cfg["blocksworld"]
    # Robotouille: the released "original" ReAct (64 messages, first reply kept); elsewhere the shared window
    assert (rob["history"], rob["window"], rob["window_keeps_first"], rob["invalid_streak"], rob["demo_observations"]) == (
        "window",
        64,
        True,
        5,
        "first",
    )
    assert (bw["history"], bw["window"], bw["window_keeps_first"], bw["invalid_streak"], bw["demo_observations"]) == (
        "window",
        128,
        False,
        None,
        "all",
    )
    # no cap of ours under the profiles: the request carries the model's whole output
    assert rob["max_llm_calls"] is None and rob["max_tokens"] is None


# -- what a benchmark declares about its ids: their one spelling and a row's place ------------------


def test_blocksworld_seed_bound_is_the_sweeps():
    from pipeline.spec import SEED_MAX
    from recap.blocksworld import SEED_MAX as BLOCKSWORLD_SEED_MAX

    assert BLOCKSWORLD_SEED_MAX == SEED_MAX


@pytest.mark.parametrize(
    "instance_id,split,task",
    [
        ("alfworld/heat/pick_heat_then_place_in_recep-Egg-None-Fridge-13/trial_1", None, None),
        ("alfworld/heat/x", "eval_out_of_distribution", "pick_heat_then_place_in_recep"),
        ("alfworld", None, None),
        ("robotouille/synchronous/6_lettuce_tomato_cheeseburger@42", None, None),
        ("robotouille/asynchronous/5_potato_soup@1", "asynchronous", "potato soup"),
        ("robotouille/x", None, "t"),
        ("blocksworld/3@1", "s", "3 blocks"),
        ("blocksworld/3@1", None, None),
        ("nowhere/1", "s", None),
    ],
)
def test_new_rows_are_placed_as_version_1_rows_are_read(instance_id, split, task):
    """The live pipeline asks the benchmark (workers.envs.registry.place_of); the reader of
    schema version 1 rows keeps its own frozen rule (schemas.labels.place_of, which cannot ask
    the benchmarks): for every built-in they agree, so old and new runs group alike."""
    from schemas.labels import place_of as version_1_place_of
    from workers.envs.registry import place_of

    assert place_of(instance_id, split, task) == version_1_place_of(instance_id, split, task)


def test_a_benchmark_declares_its_place_and_its_ids_spelling():
    from pipeline.units import canonical_instance_id
    from recap.env import UnknownInstanceError
    from workers.envs.registry import Benchmark, place_of, registered_benchmark

    class Shelf(Benchmark):
        name = "shelf"

        def list_instances(self, selector=None):
            return ["shelf/top/A"]

        def make(self, instance_id, **options):
            raise NotImplementedError

        def canonical_id(self, instance_id):
            if instance_id.endswith("!"):
                raise UnknownInstanceError(f"shelf instance {instance_id!r} shouts")
            return instance_id.lower()

        def place(self, instance_id, split=None, task=None):
            return instance_id.split("/")[1], task or "any"

    assert place_of("shelf/top/A") == ("shelf", "", "")  # not registered: the default
    assert canonical_instance_id("shelf/TOP/A") == "shelf/TOP/A"
    with registered_benchmark("shelf", Shelf()):
        assert place_of("shelf/top/A") == ("shelf", "top", "any")
        assert place_of("shelf/low/A", "ignored", "t") == ("shelf", "low", "t")
        assert canonical_instance_id("shelf/TOP/A") == "shelf/top/a"
        with pytest.raises(UnknownInstanceError, match="shouts"):
            canonical_instance_id("shelf/top/A!")
