"""The FEVER benchmark for the registry: list the paper's 200 claims (or all), make one environment.

Options of :meth:`FeverBenchmark.make`:
- ``data_dir``: the folder holding ``paper_dev.jsonl``; default by the shared rule (``$FEVER_DATA``...).
- ``wikipedia_url``: the base URL searched as ``<base>/w/index.php?search=...``; default the real site,
  or under ``wikipedia: snapshot:DIR`` the one the snapshot's run read (its recorded request URLs,
  :func:`snapshot_base_url`), so a replay need not repeat it.
- ``wikipedia``: ``live`` (default) reads that server; ``snapshot:DIR`` answers only from the
  ``wiki_pages`` table(s) in DIR (a run folder) and never reaches a server.
- ``wikipedia_rate``: requests per second per host for the whole run (default 2.0, at most
  :data:`.ratelimit.MAX_RATE`), shared by every worker of a Ray run through the run's
  :class:`.politeness.WikiPoliteness` actor, by the process's environments elsewhere.
- ``wikipedia_deadline_s``: seconds one live answer may take, retries and redirects included
  (default 60; past it the episode ends ``wiki_error``, kind ``timeout``).
- ``wikipedia_max_page_bytes``: the most decoded bytes one live answer may have (default 5 MiB;
  past it ``wiki_error``, kind ``too_large``, and nothing is stored).
- ``max_steps``: actions per episode (default 10, the paper's cap).
- ``verdict_only``: the method gives only a verdict (CoT, Standard; the pipeline sets it per
  method, :meth:`FeverBenchmark.options_for_agent`): the rules ask for a one-action plan.
- ``sample_seed``: the seed of the shuffle behind the ``paper`` selector (default 42: ReCAP, CoT,
  Standard, main.py; 233: the ReAct/Act notebooks' 200, :mod:`.claims`); read when the
  instances are listed, accepted by make() and ignored there.
- ``step_multiplier`` and ``seed`` are accepted and have no effect (a fixed cap; no randomness).
- ``page_store`` / ``limiter``: objects a caller passes in (where answers read live are kept;
  the shared per-host rate limit); defaults: the environment keeps them and hands them to the
  episode worker as ``wiki_pages``/``wiki_requests`` rows (``take_records``), the run's
  shared limiter (:func:`run_limiter`).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import replace
from functools import lru_cache
from pathlib import Path
from typing import Any

from recap.config import AgentConfig
from recap.env import Environment
from workers.envs.data_sources import DataFolder
from workers.envs.options import EnvOption, episode, run
from workers.envs.registry import Benchmark, RunService

from . import protocol
from .claims import BENCHMARK_NAME, PAPER_SEED, check_sample_seed, find_claim, load_claims, resolve_data_dir, select
from .data_folders import FOLDER
from .demo import demonstration_for
from .env import DEFAULT_MAX_STEPS, FeverEnvironment
from .pages import PageStore, RunRecords, Snapshot, snapshot_key
from .ratelimit import DEFAULT_BURST, DEFAULT_RATE, POLITENESS_VAR, RateLimiter, check_rate, shared_limiter
from .replay import replay_fever_file
from .wiki import (
    DEFAULT_DEADLINE_S,
    DEFAULT_MAX_PAGE_BYTES,
    DEFAULT_POLICY,
    DEFAULT_WIKIPEDIA_URL,
    LiveSource,
    RetryPolicy,
    SnapshotSource,
    WikiSource,
    check_deadline,
    check_max_page_bytes,
)

LIVE = "live"
SNAPSHOT_PREFIX = "snapshot:"


#: the options a sweep may give (:mod:`workers.envs.options`). What an episode does: the Wikipedia
#: source (server or snapshot), the step cap (its default is the method's: ReCAP released has
#: its safety bound, :func:`.protocol.env_options`), a verdict-only plan. How it is run: where the
#: claims are read from, the request rate and the limits of one live answer (past them the
#: episode ends ``wiki_error``, which a resume retries), and ``sample_seed``, which picks the
#: instances of the ``paper`` selector (their ids already say which claims run; one claim's
#: episode is the same whichever sample holds it)
FEVER_OPTIONS: Mapping[str, EnvOption] = {
    "data_dir": run(),
    "wikipedia_url": episode(DEFAULT_WIKIPEDIA_URL),
    "wikipedia": episode(LIVE),
    "wikipedia_rate": run(),
    "wikipedia_deadline_s": run(),
    "wikipedia_max_page_bytes": run(),
    "max_steps": episode(),
    "verdict_only": episode(),
    "sample_seed": run(),
}


def check_wikipedia_url(url: Any) -> str:
    """``url`` when it is an http(s) base URL, else ValueError naming the option."""
    if not isinstance(url, str) or not url.startswith(("http://", "https://")) or len(url.rstrip("/")) <= len("https://"):
        raise ValueError(f"wikipedia_url must be an http(s) base URL such as {DEFAULT_WIKIPEDIA_URL}, got {url!r}")
    return url.rstrip("/")


def snapshot_dir(wikipedia: Any) -> Path | None:
    """The folder of ``snapshot:DIR``; None for ``live``; ValueError for anything else."""
    if wikipedia == LIVE:
        return None
    if isinstance(wikipedia, str) and wikipedia.startswith(SNAPSHOT_PREFIX) and wikipedia[len(SNAPSHOT_PREFIX) :].strip():
        return Path(wikipedia[len(SNAPSHOT_PREFIX) :].strip()).expanduser()
    raise ValueError(f"wikipedia must be {LIVE!r} or 'snapshot:DIR' (a folder holding wiki_pages tables), got {wikipedia!r}")


def run_limiter(rate: float = DEFAULT_RATE, burst: int = DEFAULT_BURST) -> RateLimiter:
    """The run's shared limiter: the WikiPoliteness actor :data:`.ratelimit.POLITENESS_VAR` names
    (set only on a Ray run's episode workers), else this process's bucket (:func:`.ratelimit.shared_limiter`)."""
    name = os.environ.get(POLITENESS_VAR)
    if not name:
        return shared_limiter(rate, burst)
    # here, not at the top: the actor's module loads Ray, which only a Ray run's workers need
    # (recap env play and the tests without Ray stay Ray-free)
    from .politeness import RemoteLimiter

    return RemoteLimiter(name, rate, burst)


@lru_cache(maxsize=8)
def _snapshot(folder: Path, files: tuple[tuple[str, int, int], ...]) -> Snapshot:
    """The snapshot of ``folder`` as its table files (``files``: :func:`.pages.snapshot_key`) are now."""
    return Snapshot(folder)


def wiki_source(
    wikipedia: str = LIVE,
    *,
    page_store: PageStore | None = None,
    limiter: RateLimiter | None = None,
    rate: float = DEFAULT_RATE,
    policy: RetryPolicy = DEFAULT_POLICY,
) -> WikiSource:
    """The source of search answers for a ``wikipedia`` setting (a snapshot is loaded once per
    process for as long as its table files are unchanged: names, sizes, mtimes); live answers wait
    for ``limiter``, by default the run's shared one at ``rate`` (:func:`run_limiter`)."""
    folder = snapshot_dir(wikipedia)
    if folder is None:
        return LiveSource(page_store, limiter=limiter if limiter is not None else run_limiter(rate), policy=policy)
    resolved = folder.resolve()
    return SnapshotSource(_snapshot(resolved, snapshot_key(resolved)))


def snapshot_base_url(snapshot: Snapshot) -> str:
    """The ``wikipedia_url`` a snapshot was recorded from (its request URLs, checked against its
    sealed manifest when it loaded): what a replay searches when it does not name one. ValueError
    (one line) when it holds no request, or requests to several servers (then name one)."""
    servers = snapshot.servers()
    if len(servers) == 1:
        return servers[0]
    if not servers:
        raise ValueError(f"the snapshot {str(snapshot.folder)!r} holds no search request; give wikipedia_url")
    raise ValueError(
        f"the snapshot {str(snapshot.folder)!r} holds pages of {len(servers)} servers ({', '.join(servers)}); "
        "give wikipedia_url to say which one the episodes search"
    )


class FeverBenchmark(Benchmark):
    """FEVER's registry entry: claims from ``paper_dev.jsonl``, observations from Wikipedia or a snapshot."""

    name = BENCHMARK_NAME

    def declared_options(self) -> Mapping[str, EnvOption]:
        """:data:`FEVER_OPTIONS`."""
        return FEVER_OPTIONS

    def run_services(self) -> tuple[RunService, ...]:
        """One Wikipedia politeness actor per run, shared by every worker (:func:`run_limiter` finds it)."""
        return (RunService("wiki-politeness", POLITENESS_VAR, "workers.envs.fever.politeness:WikiPoliteness"),)

    def replay_file(self, path: str, options: Mapping[str, object]) -> tuple[bool, str]:
        """A FEVER trajectory (:mod:`.replay`), ``options`` overriding its own."""
        return replay_fever_file(path, options)

    def __init__(self, data_dir: str | os.PathLike[str] | None = None) -> None:
        self.data_dir = data_dir

    def data_folders(self) -> Mapping[str, DataFolder]:
        """The claims folder (:mod:`.data_folders`)."""
        return {FOLDER.name: FOLDER}

    def profile_settings(
        self, config_cls: type[AgentConfig], profile: str, ablation: str | None, generic: dict[str, Any]
    ) -> dict[str, Any]:
        """The methods' profiles on FEVER (:mod:`.protocol`)."""
        return protocol.profile_settings(config_cls, profile, generic)

    def release_prompt_settings(self, config_cls: type[AgentConfig]) -> dict[str, Any]:
        """What ``prompts: release`` implies on FEVER (:mod:`.protocol`)."""
        return protocol.release_prompt_settings(config_cls)

    def options_for_agent(self, style: str, config: AgentConfig | None = None) -> dict[str, Any]:
        """CoT and Standard (a plan config) give only the verdict (:func:`.protocol.verdict_only`)."""
        options = {protocol.VERDICT_ONLY: True} if protocol.verdict_only(config) else {}
        return {**options, **protocol.env_options(config)}  # ReCAP released: its safety bound

    def refuses_method(self, method: str) -> str | None:
        """ADaPT: the paper has no FEVER number (:func:`.protocol.refusal`)."""
        return protocol.refusal(method)

    def list_instances(self, selector: str | None = None) -> list[str]:
        """``None``/``paper``: the paper's 200 in the release's order; ``all``: every claim in file order."""
        return self.list_instances_for(selector, {})

    def list_instances_for(self, selector: str | None, options: Mapping[str, Any]) -> list[str]:
        """:meth:`list_instances` of the claims in ``options['data_dir']`` when a sweep names one,
        ``paper`` meaning the sample of ``options['sample_seed']`` (default 42)."""
        data_dir = options.get("data_dir")
        seed = check_sample_seed(options.get("sample_seed", PAPER_SEED))
        claims = load_claims(resolve_data_dir(data_dir if data_dir is not None else self.data_dir))
        return [c.instance_id for c in select(claims, selector, seed)]

    def make(
        self,
        instance_id: str,
        *,
        data_dir: str | os.PathLike[str] | None = None,
        wikipedia_url: str | None = None,
        wikipedia: str = LIVE,
        wikipedia_rate: float = DEFAULT_RATE,
        wikipedia_deadline_s: float = DEFAULT_DEADLINE_S,
        wikipedia_max_page_bytes: int = DEFAULT_MAX_PAGE_BYTES,
        max_steps: int = DEFAULT_MAX_STEPS,
        step_multiplier: float | None = None,
        seed: int = 0,
        sample_seed: int = PAPER_SEED,
        verdict_only: bool = False,
        page_store: PageStore | None = None,
        limiter: RateLimiter | None = None,
        **unknown: Any,
    ) -> Environment:
        """A fresh environment for ``fever/<claim id>``; ValueError for an unknown or bad option."""
        if unknown:
            raise ValueError(
                f"unknown FEVER option(s) {', '.join(sorted(unknown))}; accepted: data_dir, wikipedia_url, "
                "wikipedia, wikipedia_rate, wikipedia_deadline_s, wikipedia_max_page_bytes, max_steps, verdict_only, sample_seed, step_multiplier, seed"
            )
        check_sample_seed(sample_seed)  # it chose the instances; nothing in an episode reads it
        base = check_wikipedia_url(wikipedia_url) if wikipedia_url is not None else None
        rate = check_rate(wikipedia_rate)
        policy = replace(
            DEFAULT_POLICY,
            deadline_s=check_deadline(wikipedia_deadline_s),
            max_page_bytes=check_max_page_bytes(wikipedia_max_page_bytes),
        )
        if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1:
            raise ValueError(f"max_steps must be a positive integer, got {max_steps!r}")
        if not isinstance(verdict_only, bool):
            raise ValueError(f"verdict_only must be true or false, got {verdict_only!r}")
        records = RunRecords() if page_store is None else None
        store = records.store if records is not None else page_store
        source = wiki_source(wikipedia, page_store=store, limiter=limiter, rate=rate, policy=policy)
        if base is None:
            base = snapshot_base_url(source.snapshot) if isinstance(source, SnapshotSource) else DEFAULT_WIKIPEDIA_URL
        claims = load_claims(resolve_data_dir(data_dir if data_dir is not None else self.data_dir))
        env = FeverEnvironment(
            find_claim(claims, instance_id),
            source,
            wikipedia_url=base,
            max_steps=max_steps,
            demonstration=lambda: demonstration_for(max_steps, verdict_only=verdict_only),
            verdict_only=verdict_only,
            records=records,
        )
        env.layout_seed = seed
        return env


BENCHMARK = FeverBenchmark()
