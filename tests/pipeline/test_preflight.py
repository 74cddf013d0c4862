"""The plan's preflight (pipeline.preflight.check_plan): a unit that cannot start its episode
(its data folder is missing, its method's demonstration does not render for its task kind) is
one line before anything is written, not an ``env_error`` result that counts as done."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import recap.blocksworld as blocksworld
from pipeline.errors import SpecError
from pipeline.preflight import MESSAGE_MAX, check_plan
from pipeline.spec import parse_spec
from pipeline.units import expand
from recap.env import Demonstration
from workers.envs import data_paths, registry

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"
HAVE_ROBOTOUILLE = (SHARED / "robotouille" / "domain" / "robotouille.json").is_file()
HAVE_ALFWORLD = (SHARED / "alfworld" / "json_2.1.1").is_dir()

SPEC = """run: preflight
output: {out}
models:
  - model: offline/expert
methods:
{methods}
environments:
{envs}
seeds: [0, 1]
"""
BLOCKS = '  - benchmark: blocksworld\n    tasks: ["3"]'
ROBOTOUILLE = "  - benchmark: robotouille\n    tasks: [synchronous/2]\n    limit: 1"


def methods(*names: str) -> str:
    return "\n".join(f"  - method: {n}" for n in names)


def plan_of(methods_text: str, envs_text: str, out: str = "/tmp/never-written"):
    return expand(parse_spec(SPEC.format(out=out, methods=methods_text, envs=envs_text), "sweep.yaml"))


def refusal(plan) -> str:
    with pytest.raises(SpecError) as info:
        check_plan(plan)
    message = str(info.value)
    assert "\n" not in message and len(message) <= MESSAGE_MAX
    return message


@pytest.fixture
def count_opens(monkeypatch):
    """The instance ids make_env opened (the preflight goes through the registry)."""
    opened: list[str] = []
    real = registry.make_env

    def counting(instance_id, **options):
        opened.append(instance_id)
        return real(instance_id, **options)

    monkeypatch.setattr(registry, "make_env", counting)
    return opened


@pytest.fixture
def no_data(tmp_path, monkeypatch):
    """No benchmark data anywhere: empty HOME, no variables, no ../shared/data."""
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    for var in ("RECAP_EVAL_CACHE", "ROBOTOUILLE_DATA", "ALFWORLD_DATA", "ALFWORLD_DATA_2_1_2"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr(data_paths, "CHECKOUT_DATA_ROOT", tmp_path / "shared" / "data")
    return tmp_path


def demo_without(style: str, name: str) -> Demonstration:
    """Blocksworld's demonstration lacking one style's replies (a fresh name: rendered demos are
    cached by name)."""
    d = blocksworld.DEMONSTRATION
    return Demonstration(name=name, make_env=d.make_env, replies={k: v for k, v in d.replies.items() if k != style})


# --------------------------------------------------------------------------------------------
def test_a_good_plan_passes_silently(count_opens, capsys):
    check_plan(plan_of(methods("recap", "react", "act", "cot", "standard", "adapt"), BLOCKS))
    assert capsys.readouterr() == ("", "")
    assert count_opens == ["blocksworld/3@1"]  # one instance serves all six methods


def test_a_demonstration_without_replies_for_the_style(monkeypatch):
    monkeypatch.setattr(blocksworld, "DEMONSTRATION", demo_without("cot", "blocksworld/demo-no-cot"))
    message = refusal(plan_of(methods("recap", "cot"), BLOCKS))
    assert message == (
        "methods[1] (cot) cannot run on blocksworld/3: demonstration 'blocksworld/demo-no-cot' has no replies for style 'cot'"
    )


def test_a_demonstration_that_does_not_reach_its_goal(monkeypatch):
    d = blocksworld.DEMONSTRATION
    replies = dict(d.replies, standard=[{"actions": ["pick up B"]}])  # stops far from the goal
    monkeypatch.setattr(blocksworld, "DEMONSTRATION", Demonstration("blocksworld/demo-short", d.make_env, replies))
    message = refusal(plan_of(methods("recap", "react", "standard"), BLOCKS))
    assert message.startswith(
        "methods[2] (standard) cannot run on blocksworld/3: demonstration 'blocksworld/demo-short' "
        "does not reach the goal with StandardAgent"
    )


def test_a_label_names_the_method(monkeypatch):
    monkeypatch.setattr(blocksworld, "DEMONSTRATION", demo_without("react", "blocksworld/demo-no-react"))
    text = "  - method: recap\n  - method: react\n    label: mine\n    profile: paper"
    message = refusal(plan_of(text, BLOCKS))
    assert message.startswith("methods[1] (mine) cannot run on blocksworld/3: demonstration 'blocksworld/demo-no-react'")


def test_missing_data_folder_names_the_benchmark(no_data):
    message = refusal(plan_of(methods("recap"), ROBOTOUILLE))
    assert message.startswith("environments[0] (robotouille): cannot find its data: no Robotouille data folder")
    assert "recap data fetch robotouille" in message and "recap data list" in message


def test_a_data_variable_naming_an_empty_folder(no_data, monkeypatch):
    empty = no_data / "empty"
    empty.mkdir()
    monkeypatch.setenv("ROBOTOUILLE_DATA", str(empty))
    message = refusal(plan_of(methods("recap", "react"), BLOCKS + "\n" + ROBOTOUILLE))
    assert message.startswith(
        f"environments[1] (robotouille): cannot find its data: '{empty}' (from ROBOTOUILLE_DATA) is not a Robotouille data folder"
    )
    assert message.endswith("`recap data list` shows where it looks, `recap data fetch robotouille` gets it")


def test_an_option_the_benchmark_refuses():
    envs = ROBOTOUILLE + "\n    options: {engine: bogus}"
    message = refusal(plan_of(methods("recap"), envs))
    assert message.startswith("environments[0] (robotouille): cannot open robotouille/synchronous/")
    assert message.endswith("ValueError: unknown Robotouille engine 'bogus'; engines: ours, real")


def test_one_open_per_task_kind_and_option_set(count_opens):
    envs = '  - benchmark: blocksworld\n    tasks: ["3", "4"]'
    plan = plan_of(methods("recap", "react", "cot"), envs)
    assert len(plan.units) == 6 * 3 * 2  # 6 instances x 3 methods x 2 seeds
    check_plan(plan)
    assert count_opens == ["blocksworld/3@1", "blocksworld/4@1"]


def test_all_alfworld_games_open_a_handful(count_opens, monkeypatch):
    assert HAVE_ROBOTOUILLE and HAVE_ALFWORLD, f"the tests need the benchmark data in {SHARED}"
    monkeypatch.setenv("ROBOTOUILLE_DATA", str(SHARED / "robotouille"))
    monkeypatch.setenv("ALFWORLD_DATA", str(SHARED / "alfworld"))
    envs = "  - benchmark: alfworld\n    tasks: [all]\n" + ROBOTOUILLE.replace("limit: 1", "limit: 3")
    plan = plan_of(methods("recap", "react", "cot"), envs)
    assert len({u.instance_id for u in plan.units}) == 134 + 3
    check_plan(plan)
    kinds = sorted({i.split("/")[1] for i in count_opens if i.startswith("alfworld/")})
    assert kinds == ["clean", "cool", "examine", "heat", "put", "puttwo"]
    # ALFWorld: 6 task types x 2 option sets (recap sees the valid actions, react and cot do not);
    # Robotouille: one kitchen for every method
    assert len(count_opens) == 6 * 2 + 1


# --------------------------------------------------------------------------------------------
# through the CLI (pipeline.cli wires check_plan into run, resume and estimate)
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "argv",
    [["run", "{spec}", "--progress", "off"], ["run", "{spec}", "--dry-run"], ["estimate", "{spec}"]],
    ids=["run", "dry-run", "estimate"],
)
def test_cli_refuses_a_unit_that_cannot_start(no_data, monkeypatch, capsys, argv):
    import pipeline.cli as cli
    import pipeline.cli.run as run_command

    def never(*_a, **_k):
        raise AssertionError("the run started: the preflight did not stop it")

    monkeypatch.setattr(run_command, "_execute", never)  # no Ray, no episodes, whatever happens
    out = no_data / "out"
    spec = no_data / "sweep.yaml"
    spec.write_text(SPEC.format(out=out, methods=methods("recap"), envs=ROBOTOUILLE))
    code = cli.main([a.replace("{spec}", str(spec)) for a in argv])
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("recap: error: ")
    assert "environments[0] (robotouille): cannot find its data: no Robotouille data folder" in err[0]
    if argv[0] == "run":
        assert err[0].startswith("recap: error: sweep.yaml: environments[0] (robotouille)")
        assert captured.out == ""
    assert not out.exists()


def test_asking_litellm_for_key_names_first_keeps_the_bundled_tokenizer():
    """A process whose first litellm import happened while preflight asked litellm for a
    provider's key names (with the environment emptied) lost TIKTOKEN_CACHE_DIR when the
    environment was restored, and counted OpenAI prompts by the estimate ever after (a fresh
    interpreter, so the import really is the first)."""
    code = (
        "from pipeline.preflight import key_variables\n"
        "from pipeline.spec import ModelSpec\n"
        "from workers.llm.tokens import count_prompt_tokens\n"
        "key_variables(ModelSpec(model='gpt-4o'))\n"
        "print(count_prompt_tokens('openai/gpt-4o', [{'role': 'user', 'content': 'hi'}]).source)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False)
    assert done.stdout.strip().splitlines()[-1:] == ["tokenizer"], done.stderr[-2000:]
