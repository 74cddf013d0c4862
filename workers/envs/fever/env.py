"""One FEVER claim as an environment: search and read Wikipedia, then give a verdict.

Behaves as the release's ``WikiEnv`` wrapped in ``FeverWrapper`` (fever-recap/hotpotqa/wikienv.py,
wrappers.py): the first observation is ``Claim: <claim>``; ``search[entity]`` shows the first five
sentences of the page the search lands on, or "Could not find ..." with similar titles, and on a
disambiguation page searches again for ``[entity]``; ``lookup[keyword]`` walks the sentences of the
current page that contain the keyword; ``finish[answer]`` ends the episode with reward 1 when the
normalised answer equals the normalised label; ``think[...]`` is acknowledged; anything else gets
"Invalid action: ..." - every one of them uses a step. On top of the release the episode ends after
``max_steps`` actions (the paper's 10). The action reaches the environment as written (only
stripped, wikienv.py:127); the release's runner lower-cases its first letter before stepping
(hotpotqa_simulator.py:41), which is the agent-facing layer's job: the class declares it
(``action_spelling = "lower_first"``) and :func:`recap.env.agent_action` applies it.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

from recap.env import PLAN_COPY_STEPS, ActionSpelling, Demonstration, EnvError, Environment, InvalidActionError, Reset, Step
from workers.envs.fever import text
from workers.envs.fever.claims import Claim
from workers.envs.fever.pages import RunRecords
from workers.envs.fever.rules import rules_text
from workers.envs.fever.wiki import WikiError, WikiSource, search_url

#: the paper's action cap for FEVER
DEFAULT_MAX_STEPS = 10
#: how often the release's disambiguation retry may nest before we stop (the release recurses
#: without bound, wikienv.py:113, and would crash; real answers to ``[entity]`` are result lists)
MAX_DISAMBIGUATION_RETRIES = 3


def _bracketed(action: str, verb: str) -> str | None:
    """The argument of ``verb[...]`` or None (wikienv.py:132-153: prefix and final bracket)."""
    if action.startswith(verb + "[") and action.endswith("]"):
        return action[len(verb) + 1 : -1]
    return None


class FeverEnvironment(Environment):
    """A FEVER claim over a :class:`~workers.envs.fever.wiki.WikiSource`; open action space, every
    action uses a step, success is reward 1 at ``finish[...]``."""

    benchmark = "fever"
    split = "dev"
    invalid_action_mode = "step"
    #: the agent-facing layer lower-cases an action's first letter (hotpotqa_simulator.py:41)
    action_spelling: ActionSpelling = "lower_first"
    partially_observed = True

    def __init__(
        self,
        claim: Claim,
        source: WikiSource,
        *,
        wikipedia_url: str,
        max_steps: int = DEFAULT_MAX_STEPS,
        demonstration: Callable[[], Demonstration | None] | None = None,
        verdict_only: bool = False,
        records: RunRecords | None = None,
    ) -> None:
        self.claim = claim
        self.instance_id = claim.instance_id
        #: the claim's gold label, recorded with the episode (EnvFacts.task) so the report can break
        #: success down by label; no prompt reads it (the agents see rules, observations, the goal)
        self.task = claim.label
        self.source = source
        self.wikipedia_url = wikipedia_url
        self.max_steps = max_steps
        self._demonstration = demonstration
        #: the method gives only a verdict (CoT, Standard): the rules ask for a one-action plan
        self.verdict_only = verdict_only
        #: the pages read live, handed to the episode worker as table rows (None: kept elsewhere)
        self.records = records
        self._started = False
        self._past_end_ok = False
        self._clear()

    def _clear(self) -> None:
        # wikienv.py:49-54: the state a reset starts from
        self.page: str | None = None
        self.lookup_keyword: str | None = None
        self.lookup_list: list[str] = []
        self.lookup_cnt = 0
        self.answer: str | None = None
        self.reward = 0
        self.obs = ""
        self._steps_taken = 0
        self._done = False

    @property
    def done(self) -> bool:
        """Whether the episode is over (a verdict was given or the step cap reached)."""
        return self._done

    # -- episode -------------------------------------------------------------------------------
    def reset(self) -> Reset:
        """Start over: ``Claim: <claim>`` (wrappers.py:166), an open action space, the claim as goal."""
        self._clear()
        self._started = True
        self.obs = text.claim_text(self.claim.claim)
        return Reset(observation=self.obs, valid_actions=None, goal=self.claim.claim)

    def step(self, action: str) -> Step:
        """One action; raises WikiError when a search answer cannot be had, EnvError before reset or after the end."""
        if not isinstance(action, str):
            raise InvalidActionError(f"a FEVER action is a string, got {type(action).__name__}")
        if not self._started:
            raise EnvError(f"{self.instance_id}: call reset() before step()")
        if self._done and self._past_end_ok and self.answer is not None:
            return Step(self.obs, None, True, self.reward == 1, self._info(True))
        if self._done:
            raise EnvError(f"{self.instance_id}: the episode is over; call reset() to play again")
        self.obs = self._act(action.strip())  # wikienv.py:127
        self._steps_taken += 1  # wikienv.py:158: every action counts, invalid ones too
        finished = self.answer is not None
        self._done = finished or self._steps_taken >= self.max_steps
        return Step(
            observation=self.obs,
            valid_actions=None,
            done=self._done,
            success=finished and self.reward == 1,
            info=self._info(finished),
        )

    def _info(self, finished: bool) -> dict[str, Any]:
        info: dict[str, Any] = {
            "steps": self._steps_taken,
            "max_steps": self.max_steps,
            "answer": self.answer,
            "reward": self.reward,
        }
        if finished:
            info["gt_answer"] = self.claim.label  # wrappers.py:192
            if self.reward != 1:  # a verdict was given: the agent finished, wrongly (not a cap)
                info["end_reason"] = "agent_done"
        elif self._done:
            info["end_reason"] = "step_cap"
        return info

    def _act(self, action: str) -> str:
        entity = _bracketed(action, "search")
        if entity is not None:
            return self._search(entity)
        keyword = _bracketed(action, "lookup")
        if keyword is not None:
            return self._lookup(keyword)
        answer = _bracketed(action, "finish")
        if answer is not None:  # wikienv.py:148-152 with wrappers.py:178-191
            self.answer = answer
            self.reward = text.reward_for(answer, self.claim.label)
            return text.finished_text(self.reward)
        if _bracketed(action, "think") is not None:
            return text.THOUGHT_ACK
        return text.invalid_action_text(action)

    def _search(self, entity: str, depth: int = 0) -> str:
        """wikienv.py:98-122; a failed search keeps the current page and lookup."""
        url = search_url(self.wikipedia_url, entity)
        html = self.source.fetch(url)
        try:
            answer = text.read_search_html(html)
        except text.UnreadableTextError as exc:
            raise WikiError("unreadable", f"the answer for {url} cannot be read as the release reads it: {exc}") from None
        if answer.titles is not None:
            return text.not_found_text(entity, answer.titles)
        if answer.disambiguation:  # wikienv.py:112-113: search again for "[entity]"
            if depth >= MAX_DISAMBIGUATION_RETRIES:
                raise WikiError("disambiguation_loop", f"{url}: still a disambiguation page after {depth} bracketed searches")
            return self._search("[" + entity + "]", depth + 1)
        assert answer.page is not None
        self.page = answer.page
        self.lookup_keyword, self.lookup_list, self.lookup_cnt = None, [], 0  # wikienv.py:122
        return text.page_observation(answer.page)

    def _lookup(self, keyword: str) -> str:
        """wikienv.py:137-147: a new keyword starts over; each call shows the next match."""
        if self.lookup_keyword != keyword:
            self.lookup_keyword = keyword
            self.lookup_list = text.lookup_sentences(self.page, keyword)
            self.lookup_cnt = 0
        out = text.lookup_text(self.lookup_cnt, self.lookup_list)
        if self.lookup_cnt < len(self.lookup_list):
            self.lookup_cnt += 1
        return out

    # -- prompt material -------------------------------------------------------------------------
    def rules(self) -> str:
        """The paper's FEVER rules in our words (:mod:`.rules`), the verdict-only form for CoT/Standard."""
        return rules_text(self.max_steps, verdict_only=self.verdict_only)

    def demonstration(self) -> Demonstration | None:
        """The one-shot demonstration, when the benchmark gave one (the methods' FEVER step adds it)."""
        return None if self._demonstration is None else self._demonstration()

    def expert_plan(self) -> list[str] | None:
        """The offline expert's play (a test double's script, not a solver): before any action, a
        search for the first page the claim's evidence cites (else the claim's leading capitalised
        words), then the label as the verdict; verdict-only methods give the verdict alone."""
        if self._done:
            return None
        verdict = f"finish[{self.claim.label}]"
        if self.verdict_only or self._steps_taken:
            return [verdict]
        entity = self.claim.evidence_pages[0] if self.claim.evidence_pages else text.leading_entity(self.claim.claim)
        return [f"search[{entity}]", verdict] if entity else [verdict]

    def take_records(self, episode_id: str, run_id: str) -> list[Any]:
        """The ``wiki_pages``/``wiki_requests`` rows of the pages read since the last call."""
        return [] if self.records is None else self.records.take(episode_id, run_id)

    def plan_copy(self) -> Environment:
        """A copy sharing this one's Wikipedia source (a deep copy cannot copy its connection and
        limiter), without a step cap, that answers steps past the end as the release's WikiEnv does:
        the finish observation again, nothing counted (wikienv.py:128-130, wrappers.py:190-191)."""
        sim = copy.copy(self)
        sim.lookup_list = list(self.lookup_list)
        sim.max_steps = PLAN_COPY_STEPS
        sim._past_end_ok = True
        return sim
