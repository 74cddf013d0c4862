"""ReAct, Act, CoT and Standard as the authors' FEVER notebooks ran them (``prompts: release``, ``first_turn: notebook``).

The release runs its FEVER baselines from notebooks (GitHub ``ReCAP-Stanford/ReCAP`` at 2fb112f,
``fever-recap/``), each with a loop of its own that none of our text layouts reproduces; the
text they send is read by ``workers/release/fever_notebooks.py`` and handed over in the
:class:`~recap.release_prompt.ReleasePrompt` (the demonstration pinned as the first user message,
the rounds, the final-round sentence, the CoT/Standard frame). What this module does, with the
notebooks' lines (cell 4 of ``React.ipynb`` / ``baseline_act.ipynb``; cell 2 of
``baseline_cot.ipynb`` / ``baseline_standard.ipynb``):

ReAct/Act (``webthink``; "cell 4:N" is line N of the cell's source, the same in both notebooks
unless said):

* no system message; the demonstration is the first user message (cell 4:14,
  ``history.append({"role": "user", "content": webthink_prompt})``; the prompt read at 4:4-9);
* each round ``i`` (``for i in range(1, 11)``, 4:24) sends one user message, ``Thought i:`` (Act:
  ``Action i:``, 4:25), after the question and a newline on round 1 (4:26-27) and after the
  final-round sentence on the last round (React 4:28-29, Act 4:29-30), appended at 4:32;
* the call carries ``stop=[f"\\nObservation {i}:"]`` (4:35) and no temperature (cell 1:11, the
  ``llm`` helper's ``temperature`` commented out); its reply is stripped (cell 1:18);
* ReAct splits the stripped reply on ``"\\nAction i: "`` into exactly a thought and an action
  (4:37); otherwise (``except:``, 4:38-44) it adds the user message ``Thought i: <the reply's
  first line>\\nAction i:`` (4:42-43) and asks again with ``stop=["\\n"]``, the stripped answer
  being the action (4:44). Act takes ``action_str.split(f"Action {i}:")[-1].strip()`` (Act 4:38;
  its ``except`` never runs: ``split`` does not raise);
* the action is stepped with only its first character lower-cased (4:46, ``action[0].lower() +
  action[1:]``: the environment's ``lower_first`` spelling), the observation has every ``\\n``
  (a backslash and an n) removed (4:47), and the round leaves one assistant message
  ``Thought i: …\\nAction i: …\\nObservation i: …\\n`` (Act: without the thought; 4:48-49):
  the model's own reply is taken out of the context (its ``messages`` row stays);
* an empty action makes ``action[0]`` raise (4:46), which the runner scores 0 (4:93-97,
  ``except Exception: rs.append(0)``): the episode ends unsuccessful;
* ten rounds without a verdict: the notebook steps ``finish[]`` (4:54-55; scored 0); here the
  environment's own cap of 10 actions ends the episode first (``step_cap``), with the same score.

CoT/Standard (``run_hotpotqa``, cell 2): one user message, the notebook's text around the
question (baseline_cot.ipynb 2:24-26, baseline_standard.ipynb 2:24-25), sent without stop or
temperature (cell 1: neither passed); the answer is the stripped reply after its last
``Answer:`` (CoT 2:30, ``response.split("Answer:")[-1].strip()``) or the whole stripped reply
(Standard 2:27, cell 1:26), stepped once as ``finish[<answer>]`` (CoT 2:32, Standard 2:30).
"""

from __future__ import annotations

from typing import Any

from recap.env import Reset
from recap.release_prompt import ReleasePrompt
from recap.runtime import Episode, EpisodeEnd


def _text(obj: dict[str, Any]) -> dict[str, Any]:
    return obj


def _raw(text: str) -> dict[str, Any]:
    return {"text": text}


def notebook_release(ep: Episode) -> ReleasePrompt | None:
    """The episode's release prompt when it asks for the notebook loop, else None."""
    release = ep.extra.get("release")
    return release if isinstance(release, ReleasePrompt) and release.first_turn == "notebook" else None


def _ask(ep: Episode, prompt: str, kind: str, stop: tuple[str, ...], context: dict[str, Any]) -> tuple[str, int]:
    """One call as the notebooks' ``llm`` makes it: (the stripped reply, its message seq)."""
    reply, seq = ep.conv.ask(prompt, kind, _text, context=context, decode=_raw, stop=stop)
    return str(reply["text"]).strip(), seq


def play_react(ep: Episode, reset: Reset, release: ReleasePrompt, with_think: bool) -> None:
    """ReAct (``with_think``) or Act, as ``webthink`` of React.ipynb / baseline_act.ipynb cell 4."""
    if release.rounds is None or release.final_round is None or release.final_sentence is None:
        raise ValueError("the notebook loop needs the release's rounds and final-round sentence")
    question = reset.observation  # env.reset(idx=idx): "Claim: ..."
    label = "Thought" if with_think else "Action"
    context = {"task": reset.goal, "depth": 0, "valid_actions": None}
    for i in range(1, release.rounds + 1):
        prompt = f"{label} {i}:"
        if i == 1:
            prompt = question + "\n" + prompt
        if i == release.final_round:
            prompt = release.final_sentence + prompt
        said, seq = _ask(ep, prompt, "observation" if i > 1 else "task", (f"\nObservation {i}:",), context)
        ep.conv.forget(seq)  # the notebook keeps its own record of the round (step_str below)
        thought: str | None = None
        if with_think:
            parts = said.split(f"\nAction {i}: ")
            if len(parts) == 2:
                thought, action = parts
            else:  # the notebook's except: re-ask for the action alone
                thought = said.split("\n")[0]
                action, seq = _ask(ep, f"Thought {i}: {thought}\nAction {i}:", "feedback", ("\n",), context)
                ep.conv.forget(seq)
        else:
            action = said.split(f"Action {i}:")[-1].strip()
        if not action:
            raise EpisodeEnd("agent_done", f"round {i}: an empty action (the notebook's action[0] raises; it scores 0)")
        ep.driver.execute(action)  # lower_first: action[0].lower() + action[1:]
        obs = ep.driver.observation.replace("\\n", "")
        step = f"Action {i}: {action}\nObservation {i}: {obs}\n"
        if thought is not None:
            step = f"Thought {i}: {thought}\n" + step
        ep.conv.history.add("assistant", "step", step)
    raise EpisodeEnd("step_cap", f"{release.rounds} rounds without a verdict (the notebook then steps finish[], scored 0)")


def play_one_call(ep: Episode, reset: Reset, release: ReleasePrompt, with_think: bool) -> None:
    """CoT (``with_think``) or Standard, as ``run_hotpotqa`` of baseline_cot.ipynb /
    baseline_standard.ipynb cell 2."""
    if release.claim_frame is None:
        raise ValueError("the notebook's one call needs the release's text around the question")
    before, after = release.claim_frame
    context = {"task": reset.goal, "depth": 0, "valid_actions": None}
    said, _seq = _ask(ep, before + reset.observation + after, "task", (), context)
    answer = said.split("Answer:")[-1].strip() if with_think else said
    ep.driver.execute(f"finish[{answer}]")
    raise EpisodeEnd("agent_done", "the one verdict was given")
