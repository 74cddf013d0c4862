"""``prompts: release``: the authors' prompt files fetched at a pinned commit, refused when absent,
and pinned as an episode's first message when asked for.

Every release file here is a fixture this test writes, laid out like the release (the paths the
loader reads), in our own words: no text of the authors' is in this repository.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import pipeline.data as data
import workers.release.folder as release_folder_mod
from pipeline.cli.data import data_main
from pipeline.errors import SpecError
from pipeline.spec import parse_spec
from pipeline.units import expand
from recap.baselines.textreply import parse_step_plan
from recap.env import DataNotFoundError
from workers.envs.data_sources import Source
from workers.envs.registry import get_benchmark
from workers.episode_worker import EpisodeRunner, release_demonstration
from workers.release.texts import few_shot_literal, release_text

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "data"
HAVE_ROBOTOUILLE = (SHARED / "robotouille" / "domain" / "robotouille.json").is_file()
REAL_MIRROR = Path("/work/.mirror/ReCAP-Stanford+ReCAP/repo")

REACT_YML = "robotouille-baselines/agents/prompt_builder/prompts/ReAct/1.0.0-original.yml"
REACT_EXAMPLE = "robotouille-baselines/agents/in_context_examples/data/synchronous/react_examples_omitted_obs/0_demo.txt"
RECAP_PY = "robotouille-recap/MATRIX/MATRIX/prompts.py"
#: the template the released ReCAP's synchronous configs name (its system text and rules)
RECAP_YML = "robotouille-recap/agents/prompt_builder/prompts/ReAct/1.3.1-last-reasoning-action-mpc.yml"
RECAP_SYSTEM = "Fixture ReCAP system line: you cook."
RECAP_RULES = "Fixture ReCAP rule one.\nFixture ReCAP rule two."
SYSTEM = "Fixture system line: act in the kitchen."
INSTRUCTIONS = "Fixture instructions: reply with one action."
#: an example file in the released layout (interactions of observation, reasoning, action)
EXAMPLE = (
    "Interaction 1\n---------------\n\n\nObservation:\nfixture kitchen, step one\n\nGoal: fixture toast\n\n\n"
    "Reasoning: Fixture thought one.\n\nAction: Fixture action one\n\n\n"
    "Interaction 2\n---------------\n\n\nObservation:\nfixture kitchen, step two\n\n\n"
    "Reasoning: Fixture thought two.\n\nAction: Finish\n"
)
#: what the loader must make of the ReAct fixture: system, instructions, the example file
REACT_TEXT = f"{SYSTEM}\n\n{INSTRUCTIONS}\n\n{EXAMPLE}"

FILES = {
    "LICENSE": "fixture licence\n",
    REACT_YML: f"version: 1.0.0\nsystem: |\n  {SYSTEM}\ninstructions: |\n  {INSTRUCTIONS}\n",
    REACT_EXAMPLE: EXAMPLE,
    RECAP_YML: (
        f"version: 1.3.1\nsystem: |\n  {RECAP_SYSTEM}\n\ninstructions: |\n  " + RECAP_RULES.replace("\n", "\n  ") + "\n\n"
    ),
    # a top-level statement that would stop the test if the file were run rather than parsed
    RECAP_PY: (
        "raise SystemExit('never executed')\n\n"
        "def get_few_shot():\n"
        "    return [{'role': 'user', 'content': 'fixture first observation'},\n"
        "            {'role': 'assistant', 'content': '{\"subtasks\": [\"a\"]}'}]\n"
    ),
}


def write_release(root: Path, files: dict[str, str] = FILES) -> Path:
    """A folder laid out like the release, holding ``files``."""
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return root


def git_repo(root: Path, files: dict[str, str] = FILES) -> str:
    """A git repository holding ``files`` in one commit; returns the commit."""
    write_release(root, files)
    env = {
        **os.environ,
        "GIT_AUTHOR_NAME": "t",
        "GIT_AUTHOR_EMAIL": "t@t",
        "GIT_COMMITTER_NAME": "t",
        "GIT_COMMITTER_EMAIL": "t@t",
    }
    for args in (["init", "-q"], ["add", "-A"], ["commit", "-q", "-m", "fixture"]):
        subprocess.run(["git", "-C", str(root), *args], check=True, env=env, capture_output=True)
    return subprocess.run(
        ["git", "-C", str(root), "rev-parse", "HEAD"], check=True, capture_output=True, text=True
    ).stdout.strip()


@pytest.fixture
def fixture_source(tmp_path, monkeypatch):
    """The release folder's source pinned to a fixture repository's commit, and a manifest of its
    files: ``(repo, manifest entries)``; the test may edit the manifest before fetching."""
    repo = tmp_path / "mirror"
    commit = git_repo(repo)
    folder = release_folder_mod.FOLDER
    monkeypatch.setattr(
        release_folder_mod,
        "FOLDER",
        dataclasses.replace(folder, sources=(Source("ReCAP", "https://invalid.example/x.git", "git", ref=commit),)),
    )
    manifests = tmp_path / "manifests"
    manifests.mkdir()
    monkeypatch.setattr(data, "MANIFEST_DIR", manifests)
    entries = {rel: hashlib.sha256(text.encode()).hexdigest() for rel, text in FILES.items()}
    data.write_manifest(manifests / "recap-release.sha256", entries)
    return repo, entries


def run_data(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    rc = data_main(list(argv), out, err)
    return rc, out.getvalue(), err.getvalue()


def test_fetch_from_a_local_git_mirror_verifies_every_file(fixture_source, tmp_path):
    repo, entries = fixture_source
    dest = tmp_path / "release"
    rc, out, err = run_data("fetch", "recap-release", "--mirror", str(repo), "--dest", str(dest))
    assert (rc, err) == (0, "")
    assert f"recap-release: {dest}: {len(entries)} files fetched and verified" in out
    assert (dest / REACT_EXAMPLE).read_text() == EXAMPLE
    assert data.read_manifest(dest / data.MANIFEST_NAME) == entries
    rc, out, err = run_data("check", "recap-release", "--data-dir", str(dest))
    assert (rc, out, err) == (0, f"recap-release: {dest} (data_dir): {len(entries)} files checked: OK\n", "")


def test_a_file_that_does_not_match_the_manifest_is_refused_and_nothing_is_written(fixture_source, tmp_path):
    repo, entries = fixture_source
    entries = {**entries, REACT_YML: hashlib.sha256(b"the pinned text").hexdigest()}
    data.write_manifest(data.MANIFEST_DIR / "recap-release.sha256", entries)
    dest = tmp_path / "out" / "release"
    rc, _out, err = run_data("fetch", "recap-release", "--mirror", str(repo), "--dest", str(dest))
    assert rc == 1
    assert err.startswith(f"recap: error: data fetch: recap-release: {REACT_YML} from {repo}@")
    assert "does not match the manifest" in err and err.rstrip().endswith("nothing was written")
    assert not (tmp_path / "out").exists()


def test_a_mirror_that_is_not_a_repository_is_refused(fixture_source, tmp_path):
    plain = write_release(tmp_path / "plain")
    rc, _out, err = run_data("fetch", "recap-release", "--mirror", str(plain), "--dest", str(tmp_path / "d"))
    assert (rc, err) == (
        1,
        f"recap: error: data fetch: recap-release: {plain} is not a git repository (the mirror of ReCAP must be a clone of it); nothing was written\n",
    )


def test_the_release_is_not_part_of_all():
    # fetched on request only: SWE-bench Verified (from the hub or a local copy) and the authors' release
    assert [name for name, f in data.folders().items() if not f.in_all] == ["swebench-verified", "recap-release"]


@pytest.mark.skipif(not REAL_MIRROR.is_dir(), reason=f"no local mirror of the authors' repository at {REAL_MIRROR}")
def test_fetch_from_the_real_mirror_matches_the_pinned_manifest(tmp_path):
    dest = tmp_path / "release"
    rc, out, err = run_data("fetch", "recap-release", "--mirror", str(REAL_MIRROR), "--dest", str(dest))
    n = len(data.read_manifest(data.MANIFEST_DIR / "recap-release.sha256"))
    assert (rc, err) == (0, "")
    assert f"{n} files fetched and verified" in out


def test_python_prompt_files_are_parsed_never_run(tmp_path):
    write_release(tmp_path)
    assert few_shot_literal(FILES[RECAP_PY], "get_few_shot")[0] == {"role": "user", "content": "fixture first observation"}
    text = release_text(tmp_path, "recap", "robotouille", "synchronous", "6_x")
    assert text.text == f'user: fixture first observation\nassistant: {{"subtasks": ["a"]}}\n\n{RECAP_SYSTEM}\n\n{RECAP_RULES}'
    assert [p.path for p in text.parts] == [RECAP_PY, RECAP_YML]
    # the asynchronous configs name the -async template (absent here: refused, naming the fetch)
    with pytest.raises(DataNotFoundError, match=r"1\.3\.1-last-reasoning-action-mpc-async\.yml is missing .*recap data fetch"):
        release_text(tmp_path, "recap", "robotouille", "asynchronous", "6_x")
    assert release_text(tmp_path, "react", "robotouille", "synchronous", "6_x").text == REACT_TEXT


# --------------------------------------------------------------------------------------------
# the sweep side

SPEC = """run: release-prompts
output: {out}
models:
  - model: offline/expert
methods:
  - method: react
    prompts: {prompts}
environments:
{envs}
seeds: [0]
"""
BLOCKS = '  - benchmark: blocksworld\n    tasks: ["3"]\n    limit: 1'
ROBOTOUILLE = "  - benchmark: robotouille\n    tasks: [synchronous/0]\n    limit: 1"


def _env(tmp_path: Path, release: Path | None) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "RECAP_RELEASE_DATA"}
    env.update(PYTHONPATH=str(ROOT), RECAP_EVAL_CACHE=str(tmp_path / "cache"), LITELLM_LOCAL_MODEL_COST_MAP="True")
    env["RAY_USAGE_STATS_ENABLED"] = "0"
    if release is not None:
        env["RECAP_RELEASE_DATA"] = str(release)
    return env


def test_run_refuses_release_prompts_when_the_release_is_missing(tmp_path):
    if (SHARED / "recap-release").exists():
        pytest.skip(f"{SHARED / 'recap-release'} exists: the release cannot be missing here")
    out = tmp_path / "run"
    spec = tmp_path / "sweep.yaml"
    spec.write_text(SPEC.format(out=out, prompts="release", envs=BLOCKS))
    done = subprocess.run(
        [sys.executable, "-m", "pipeline.cli", "run", str(spec)],
        cwd=ROOT,
        env=_env(tmp_path, None),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2
    assert done.stderr == (
        f"recap: error: {spec.name}: methods[0] (react[release-prompts]): prompts: release: the authors' released "
        "prompt files (recap-release) are not found: run `recap data fetch recap-release`\n"
    )
    assert not out.exists()


def test_a_benchmark_without_released_prompts_is_refused(tmp_path, monkeypatch):
    monkeypatch.setenv("RECAP_RELEASE_DATA", str(write_release(tmp_path / "release")))
    with pytest.raises(SpecError) as info:
        expand(parse_spec(SPEC.format(out=tmp_path / "run", prompts="release", envs=BLOCKS), "sweep.yaml"))
    assert str(info.value) == (
        "methods[0] (react[release-prompts]): prompts: release: the release has no prompts for benchmark "
        "'blocksworld' (use prompts: ours there)"
    )


@pytest.mark.skipif(not HAVE_ROBOTOUILLE, reason=f"no Robotouille data at {SHARED / 'robotouille'}")
def test_unit_hash_covers_the_released_text_and_ours_is_unchanged(tmp_path, monkeypatch):
    release = write_release(tmp_path / "release")
    monkeypatch.setenv("RECAP_RELEASE_DATA", str(release))
    ours = expand(parse_spec(SPEC.format(out=tmp_path / "run", prompts="ours", envs=ROBOTOUILLE), "s.yaml")).units[0]
    first = expand(parse_spec(SPEC.format(out=tmp_path / "run", prompts="release", envs=ROBOTOUILLE), "s.yaml")).units[0]
    assert "prompts" not in json.loads(ours.method_config)  # units planned before the field keep their hash
    digest = hashlib.sha256(REACT_TEXT.encode()).hexdigest()
    assert json.loads(first.method_config)["prompts"] == f"release:{digest}"
    (release / REACT_EXAMPLE).write_text("Another example.\n")
    second = expand(parse_spec(SPEC.format(out=tmp_path / "run", prompts="release", envs=ROBOTOUILLE), "s.yaml")).units[0]
    assert len({ours.unit_id, first.unit_id, second.unit_id}) == 3


class _Expert:
    """Offline client double: the expert's next action as a ReAct reply (JSON, or the released
    "Reasoning:" / "Action:" lines when the request is not in JSON mode)."""

    def complete(self, request):
        from recap.llm import LLMResponse

        plan = request.hints.get("expert_plan") or ["noop"]
        text = json.dumps({"think": "next", "action": plan[0]}) if request.json_mode else f"Reasoning: next\nAction: {plan[0]}"
        return LLMResponse(text, model="test/expert", test_double=True)


class _Factory:
    writes_llm_calls = False

    def client(self, model):
        return _Expert()


@pytest.mark.skipif(not HAVE_ROBOTOUILLE, reason=f"no Robotouille data at {SHARED / 'robotouille'}")
def test_a_release_prompts_episode_pins_the_released_text_first(tmp_path, monkeypatch):
    release = write_release(tmp_path / "release")
    monkeypatch.setenv("RECAP_RELEASE_DATA", str(release))
    unit = expand(parse_spec(SPEC.format(out=tmp_path / "run", prompts="release", envs=ROBOTOUILLE), "s.yaml")).units[0]
    rows: list[dict] = []
    runner = EpisodeRunner(
        "w0", "run", _Factory(), send=lambda batch: rows.extend(batch.get("messages", [])), wait=lambda _ref: None
    )
    outcome = runner.run_unit(unit.work(), 1)
    assert outcome.crash is None and outcome.result is not None and outcome.result.success
    messages = sorted(rows, key=lambda r: r["seq"])
    # the released structure (serializer.py:53-57, retrieve_example.py:27-37): the template's system
    # text, its instructions, each example interaction as a user/assistant pair; then the first
    # turn, the observation alone (no system text or rules of ours)
    first = [(m["role"], m["kind"], m["pinned"], m["content"]) for m in messages[:6]]
    from workers.envs.registry import make_env

    start = make_env(unit.instance_id).reset()
    assert first == [
        ("system", "release", True, SYSTEM),
        ("user", "release", True, INSTRUCTIONS),
        ("user", "release", True, "fixture kitchen, step one\n\nGoal: fixture toast\n\n"),
        ("assistant", "release", True, "Reasoning: Fixture thought one.\n\nAction: Fixture action one"),
        ("user", "release", True, "fixture kitchen, step two\n\n"),
        ("assistant", "release", True, "Reasoning: Fixture thought two.\n\nAction: Finish"),
    ]
    assert (messages[6]["role"], messages[6]["kind"], messages[6]["content"]) == (
        "user",
        "task",
        f"Observation:\n{start.observation}" + ("" if start.goal in start.observation else f"\n\nGoal: {start.goal}"),
    )
    assert messages[7]["content"].startswith("Reasoning: next\nAction: ")  # the released reply format, chosen

    # a release file edited after the plan: the episode is not played with other text than hashed
    (release / REACT_EXAMPLE).write_text("Edited after the plan.\n")
    with pytest.raises(RuntimeError, match=r"changed since the plan"):
        release_demonstration(unit.work(), runner._agent(unit.work()))
    assert runner.run_unit(unit.work(), 2).result.end_reason == "env_error"


def test_release_prompts_select_the_released_reply_format_and_refuse_a_contradiction():
    from recap.baselines.act import ActConfig
    from recap.baselines.react import ReActConfig
    from recap.config import ConfigError, build_config

    robot = build_config(ReActConfig, benchmark=get_benchmark("robotouille"), prompts="release")
    assert (robot.reply_format, robot.json_mode, robot.text_layout) == ("text", False, "labelled")
    alf = build_config(ReActConfig, benchmark=get_benchmark("alfworld"), prompts="release")
    assert (alf.reply_format, alf.json_mode, alf.text_layout) == ("text", False, "yao")
    assert build_config(ActConfig, benchmark=get_benchmark("alfworld"), prompts="release").reply_format == "json"
    assert build_config(ReActConfig, benchmark=get_benchmark("robotouille")).reply_format == "json"  # ours: unchanged
    from recap.baselines.cot import PlanConfig

    plan = build_config(PlanConfig, benchmark=get_benchmark("robotouille"), prompts="release")
    assert (plan.reply_format, plan.json_mode) == ("text", False)  # the I/O agents' plain-text plan
    assert build_config(PlanConfig, benchmark=get_benchmark("robotouille")).reply_format == "json"
    from recap.baselines.adapt import ADaPTConfig

    adapt = build_config(ADaPTConfig, benchmark=get_benchmark("robotouille"), prompts="release")
    assert (adapt.algorithm, adapt.json_mode) == ("plan_once", False)  # the released prompts' algorithm
    with pytest.raises(ConfigError) as info:
        build_config(ADaPTConfig, benchmark=get_benchmark("robotouille"), prompts="release", algorithm="as_needed")
    assert str(info.value) == (
        'prompts: release asks for the released settings (algorithm: "plan_once"); drop the contradicting setting'
    )
    with pytest.raises(ConfigError) as info:
        build_config(ReActConfig, benchmark=get_benchmark("robotouille"), prompts="release", reply_format="json")
    assert str(info.value) == (
        'prompts: release asks for the released reply format (reply_format: "text"); drop the contradicting setting'
    )


@pytest.mark.skipif(not HAVE_ROBOTOUILLE, reason=f"no Robotouille data at {SHARED / 'robotouille'}")
def test_a_release_prompts_recap_episode_frames_the_released_demo_and_template(tmp_path, monkeypatch):
    from workers.envs.registry import make_env
    from workers.llm.direct import LiteLLMClient
    from workers.llm.providers import DeploymentConfig

    class Experts:
        writes_llm_calls = False

        def client(self, model):
            return LiteLLMClient(DeploymentConfig(model="offline/expert"))

    monkeypatch.setenv("RECAP_RELEASE_DATA", str(write_release(tmp_path / "release")))
    spec = SPEC.replace("method: react", "method: recap").format(out=tmp_path / "run", prompts="release", envs=ROBOTOUILLE)
    unit = expand(parse_spec(spec, "s.yaml")).units[0]
    rows: list[dict] = []
    runner = EpisodeRunner(
        "w0", "run", Experts(), send=lambda batch: rows.extend(batch.get("messages", [])), wait=lambda _ref: None
    )
    outcome = runner.run_unit(unit.work(), 1)
    assert outcome.crash is None and outcome.result is not None
    assert (outcome.result.success, outcome.result.end_reason) == (True, "success")
    messages = sorted(rows, key=lambda r: r["seq"])
    start = make_env(unit.instance_id).reset()
    # chatbot.py:401-407: the example joined one role: content line per message, framed, as the one
    # fixed user message (no system message); chatbot.py:247-261: the template's system text and
    # rules, the observation and the goal in the first prompt; none of our system text or rules
    assert [(m["role"], m["kind"], m["pinned"], m["content"]) for m in messages[:2]] == [
        (
            "user",
            "release",
            True,
            "Below is a worked example of preparing an onion and cheese sandwich:\n"
            'user: fixture first observation\nassistant: {"subtasks": ["a"]}\n\nEXAMPLE OVER.\n    ',
        ),
        (
            "user",
            "task",
            True,
            f"\n{RECAP_SYSTEM}\n        \nThe environment's rules:\n{RECAP_RULES}\n\n{start.observation}\n\n"
            f"You are to prepare a new meal. The goal is described as follows:\n{start.goal}\n\n"
            "Begin the task now. Remember to write more than a single subtask.\n",
        ),
    ]
    assert messages[2]["role"] == "assistant" and json.loads(messages[2]["content"])["subtasks"]
    # the tenth call's prompt carries the released rules reminder (chatbot.py:431-439), framed as
    # released: the rules between a sentence and an end marker, then the prompt it rides on
    reminders = [m for m in messages if "RULES END" in m["content"]]
    assert len(reminders) == 1 and reminders[0]["role"] == "user"
    head = f"Many turns have passed, so here are the operating rules again, lest they slip your mind:\n\n{RECAP_RULES}\n\nRULES END\n\n"
    assert reminders[0]["content"].startswith(head) and reminders[0]["content"][len(head)] != "\n"
    ours = make_env(unit.instance_id).rules()
    assert not any(ours in m["content"] for m in messages)  # our rules text is never sent


IO_YML = "robotouille-baselines/agents/prompt_builder/prompts/IO/1.0.0-io.yml"
IOCOT_YML = "robotouille-baselines/agents/prompt_builder/prompts/IO/1.1.0-io-cot.yml"
IO_EXAMPLE = "robotouille-baselines/agents/in_context_examples/data/synchronous/io_examples/0_demo.txt"
IOCOT_EXAMPLE = "robotouille-baselines/agents/in_context_examples/data/synchronous/io-cot_examples/0_demo.txt"
#: example files in the released I/O layouts (one interaction: the observation, then the plan)
IO_EXAMPLE_TEXT = "Interaction 1\n---------------\n\n\nObservation:\nfixture kitchen\n\nGoal: fixture toast\n\n\nPlan:\nFixture one\nFixture two\n"
IOCOT_EXAMPLE_TEXT = (
    "Interaction 1\n---------------\n\n\nObservation:\nfixture kitchen\n\nGoal: fixture toast\n\n\n"
    "Action: Fixture one\nNext State Change: fixture change one\nAction: Fixture two\nNext State Change: done\n"
)
IO_FILES = {
    **FILES,
    IO_YML: f"version: 1.0.0\nsystem: |\n  {SYSTEM} (plan)\ninstructions: |\n  {INSTRUCTIONS} (plan)\n",
    IOCOT_YML: f"version: 1.1.0\nsystem: |\n  {SYSTEM} (cot)\ninstructions: |\n  {INSTRUCTIONS} (cot)\n",
    IO_EXAMPLE: IO_EXAMPLE_TEXT,
    IOCOT_EXAMPLE: IOCOT_EXAMPLE_TEXT,
}


@pytest.mark.skipif(not HAVE_ROBOTOUILLE, reason=f"no Robotouille data at {SHARED / 'robotouille'}")
@pytest.mark.parametrize("method", ["standard", "cot"])
def test_a_release_prompts_plan_episode_sends_the_released_io_messages(tmp_path, monkeypatch, method):
    """Standard/CoT on Robotouille (issue 25 item 7): the I/O agents send the template's system text,
    its instructions and each example cut by their own regexes (IO_agent.py:17-18, 37-40;
    IOCoT_agent.py:17-18, 39-40) as user/assistant pairs, then the observation alone
    (IO_agent.py:155); the released plain-text plan is selected and played to the goal."""
    from workers.envs.registry import make_env
    from workers.llm.direct import LiteLLMClient
    from workers.llm.providers import DeploymentConfig

    class Experts:
        writes_llm_calls = False

        def client(self, model):
            return LiteLLMClient(DeploymentConfig(model="offline/expert"))

    monkeypatch.setenv("RECAP_RELEASE_DATA", str(write_release(tmp_path / "release", IO_FILES)))
    spec = SPEC.replace("method: react", f"method: {method}").format(out=tmp_path / "run", prompts="release", envs=ROBOTOUILLE)
    unit = expand(parse_spec(spec, "s.yaml")).units[0]
    assert json.loads(unit.method_config)["reply_format"] == "text"
    rows: list[dict] = []
    runner = EpisodeRunner(
        "w0", "run", Experts(), send=lambda batch: rows.extend(batch.get("messages", [])), wait=lambda _ref: None
    )
    outcome = runner.run_unit(unit.work(), 1)
    assert outcome.crash is None and outcome.result is not None
    assert (outcome.result.success, outcome.result.end_reason) == (True, "success")
    messages = sorted(rows, key=lambda r: r["seq"])
    start = make_env(unit.instance_id).reset()
    tag = "plan" if method == "standard" else "cot"
    answer = (
        "Plan:\nFixture one\nFixture two\n"
        if method == "standard"
        else "Action: Fixture one\nNext State Change: fixture change one\nAction: Fixture two\nNext State Change: done\n"
    )
    request = "fixture kitchen\n\nGoal: fixture toast\n\n\n"
    assert [(m["role"], m["kind"], m["pinned"], m["content"]) for m in messages[:5]] == [
        ("system", "release", True, f"{SYSTEM} ({tag})"),
        ("user", "release", True, f"{INSTRUCTIONS} ({tag})"),
        ("user", "release", True, request),
        ("assistant", "release", True, answer),
        (
            "user",
            "task",
            True,
            f"Observation:\n{start.observation}" + ("" if start.goal in start.observation else f"\n\nGoal: {start.goal}"),
        ),
    ]
    assert messages[5]["role"] == "assistant" and len(messages) == 6
    reply = messages[5]["content"]  # the released layout, chosen: a Plan: block or Action: lines
    assert ("Plan:\n" in reply, "\nAction: " in reply) == ((True, False) if method == "standard" else (False, True))
    ours = make_env(unit.instance_id).rules()
    assert not any(ours in m["content"] for m in messages)  # our rules text is never sent


ADAPT_DIR = "robotouille-baselines/agents/prompt_builder/prompts/Adapt"
#: the planner's few-shot file in the released layout: a byte-order mark, an interaction, and one
#: without a reasoning (the released reader skips it)
PLANNER_FEWSHOT = (
    "\ufeffInteraction 1\n-------\nObservation:\nfixture kitchen\nGoal: fixture toast\n"
    "Reasoning:\nFixture plan reasoning.\nPlan:\nStep 1: fixture subtask\nExecution order: Step 1\n\n"
    "Interaction 2\n-------\nObservation:\nan interaction without a reasoning\n"
)
ADAPT_FILES = {
    **FILES,
    f"{ADAPT_DIR}/planner_system.txt": "\nFixture planner system line.\n\n",
    f"{ADAPT_DIR}/planner_fewshot.txt": PLANNER_FEWSHOT,
    f"{ADAPT_DIR}/custom-executor.yml": (
        f"version: 1.0.0\nsystem: |-\n  {SYSTEM} (executor)\ninstructions: |-\n  {INSTRUCTIONS} (executor)\n"
        "examples:\n  - observation: |\n      fixture template observation\n  - response: |\n      Reasoning: r\n      Action: a\n"
    ),
}


@pytest.mark.skipif(not HAVE_ROBOTOUILLE, reason=f"no Robotouille data at {SHARED / 'robotouille'}")
def test_a_release_prompts_adapt_episode_sends_the_released_planner_and_executor_messages(tmp_path, monkeypatch):
    """ADaPT on Robotouille (issue 25 item 7): the planner's context starts with the system file's
    text and the few-shot file's interactions as user/assistant pairs (ADaPT_agent.py:30-61), then
    the observation; each executor's with the executor template's messages and the ReAct examples
    (ADaPT_agent.py:237-243, an executor is a released ReActAgent), then the observation and its
    subtask. Nothing in the main context; none of our system text or rules; plan_once selected."""
    from workers.envs.registry import make_env
    from workers.llm.direct import LiteLLMClient
    from workers.llm.providers import DeploymentConfig

    class Experts:
        writes_llm_calls = False

        def client(self, model):
            return LiteLLMClient(DeploymentConfig(model="offline/expert"))

    monkeypatch.setenv("RECAP_RELEASE_DATA", str(write_release(tmp_path / "release", ADAPT_FILES)))
    spec = SPEC.replace("method: react", "method: adapt").format(out=tmp_path / "run", prompts="release", envs=ROBOTOUILLE)
    unit = expand(parse_spec(spec, "s.yaml")).units[0]
    assert json.loads(unit.method_config)["algorithm"] == "plan_once"
    rows: list[dict] = []
    runner = EpisodeRunner(
        "w0", "run", Experts(), send=lambda batch: rows.extend(batch.get("messages", [])), wait=lambda _ref: None
    )
    outcome = runner.run_unit(unit.work(), 1)
    assert outcome.crash is None and outcome.result is not None
    assert (outcome.result.success, outcome.result.end_reason) == (True, "success")
    messages = [(m["role"], m["kind"], m["pinned"], m["content"]) for m in sorted(rows, key=lambda r: r["seq"])]
    start = make_env(unit.instance_id).reset()
    observation = f"Observation:\n{start.observation}" + ("" if start.goal in start.observation else f"\n\nGoal: {start.goal}")
    assert messages[:4] == [
        ("system", "release", True, "Fixture planner system line."),
        ("user", "release", True, "Observation:fixture kitchen\nGoal: fixture toast"),
        ("assistant", "release", True, "Fixture plan reasoning.\nPlan:\nStep 1: fixture subtask\nExecution order: Step 1"),
        ("user", "planner_task", True, observation),
    ]
    assert messages[4][:2] == ("assistant", "reply")
    subtask = parse_step_plan(messages[4][3])[0]
    assert messages[5:12] == [
        ("system", "release", True, f"{SYSTEM} (executor)"),
        ("user", "release", True, f"{INSTRUCTIONS} (executor)"),
        ("user", "release", True, "fixture template observation"),
        ("assistant", "release", True, "Reasoning: r\nAction: a"),
        ("user", "release", True, "fixture kitchen, step one\n\nGoal: fixture toast\n\n"),
        ("assistant", "release", True, "Reasoning: Fixture thought one.\n\nAction: Fixture action one"),
        ("user", "release", True, "fixture kitchen, step two\n\n"),
    ]
    assert messages[12] == ("assistant", "release", True, "Reasoning: Fixture thought two.\n\nAction: Finish")
    assert messages[13] == ("user", "executor_task", True, f"{observation}\n\nSubtask: {subtask}")
    executors = [m for m in messages if m[1] == "executor_task"]
    assert len(executors) == len([m for m in messages if m[:2] == ("system", "release")]) - 1  # one set per executor
    ours = make_env(unit.instance_id).rules()
    assert not any(ours in m[3] for m in messages)  # our rules text is never sent
