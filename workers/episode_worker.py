"""The episode worker: a Ray actor that hosts one environment and one agent and plays units.

Why an actor per worker (not a task per episode): an environment can be expensive to load
(ALFWorld games, Robotouille data), an agent renders its demonstration once per settings, and a
long-lived process keeps both warm between units. The driver hands a worker one unit at a time;
the worker builds the environment, runs the agent against the model client, forwards the
agent's records (messages, tree nodes, steps, and LLM calls unless the gateway writes those
itself) to the sink in batches, and returns a plain summary. It never writes the terminal
``episodes`` row: the driver does, after the attempt ends, so a worker that dies mid-episode
cannot leave a duplicate.

The module imports Ray only inside :func:`worker_actor`, so the pieces (agent construction,
the client wrapper, the record forwarder) are usable and testable without a cluster.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import threading
import time
import traceback
from collections.abc import Callable, Mapping
from typing import Any, Protocol

import recap.methods as methods
from recap.agent import Agent
from recap.config import ConfigError
from recap.env import EnvError, Environment
from recap.llm import LLMClient, LLMError, LLMRequest, LLMResponse
from recap.release_prompt import ReleasePrompt
from schemas.outcomes import Crash, EnvFacts, EpisodeOutcome, EpisodeResult, UnitWork
from schemas.records import CallRecord
from schemas.tables import check_vocabulary, record_to_row
from workers import agents as _package_agents  # noqa: F401  registers mini_swe & co. in driver and workers alike
from workers.envs import registry  # called through the module: a test may swap make_env there
from workers.envs.registry import place_of
from workers.log_setup import configure_from_env
from workers.release.texts import release_folder, release_prompt, release_text

log = logging.getLogger(__name__)

OFFLINE_PREFIX = "offline/"


# --------------------------------------------------------------------------------------------
# agents
# --------------------------------------------------------------------------------------------
def build_agent(
    method: str,
    *,
    profile: str | None = None,
    ablation: str | None = None,
    settings: Mapping[str, Any] | None = None,
    benchmark: str | None = None,
) -> Agent:
    """The agent for a method name + profile + ablation + settings (``recap.methods.make_agent``).

    ``benchmark`` is a registered benchmark's name: what its profiles mean there is what that
    benchmark declares (:class:`recap.config.BenchmarkProtocol`). Unknown methods, benchmarks
    or settings raise :class:`recap.config.ConfigError` (a bad setting's KeyError/TypeError/
    ValueError is translated, so callers report one error type).
    """
    if method not in methods.METHODS:  # read at call time: methods may be registered later
        raise ConfigError(f"unknown method {method!r}; known: {', '.join(sorted(methods.METHODS))}")
    try:
        protocol = registry.get_benchmark(benchmark) if benchmark is not None else None
    except registry.UnknownInstanceError as exc:
        raise ConfigError(str(exc)) from None
    try:
        return methods.make_agent(method, profile=profile, ablation=ablation, benchmark=protocol, **dict(settings or {}))
    except ConfigError:
        raise
    except (KeyError, TypeError, ValueError) as exc:
        raise ConfigError(str(exc).strip("'\"")) from None


def env_options_for(unit: UnitWork, agent: Agent) -> dict[str, Any]:
    """The make() options of a unit's environment: what its benchmark chooses for the agent's
    method (ALFWorld: whether observations list the valid actions), then the sweep's own
    options, which win."""
    options = dict(registry.get_benchmark(unit.benchmark).options_for_agent(agent.style, agent.config))
    options.update({k: v for k, v in unit.env_options if v is not None})
    return options


# --------------------------------------------------------------------------------------------
# model clients
# --------------------------------------------------------------------------------------------
class ClientFactory(Protocol):
    """What the driver hands each worker: a way to get a client for a model of the sweep.

    ``writes_llm_calls`` True means the client's backend (the gateway) records every call in the
    ``llm_calls`` table itself, so the worker must not forward the agent's CallRecords.
    """

    writes_llm_calls: bool

    def client(self, model: str) -> LLMClient: ...


@dataclasses.dataclass
class ClientTable:
    """The picklable :class:`ClientFactory` the driver hands its workers: one client per sweep
    model label (a ``GatewayClient``: an actor handle).

    Why here and not beside the backend that fills it (:mod:`pipeline.gateway_backend`): a worker
    unpickles its factory, and unpickling imports the class's module; this module is loaded in
    every worker anyway, the pipeline's would drag the sweep-spec parser, pydantic, pyarrow and
    numpy into each worker process (issue 37, item 3).

    A model with gateway shards has a list of clients, one per shard: the worker given index
    ``worker`` (the pool's :meth:`for_worker`) takes shard ``worker % shards`` (issue 37, item 2)."""

    clients: dict[str, Any]
    writes_llm_calls: bool = True
    worker: int = 0

    def for_worker(self, index: int) -> ClientTable:
        return dataclasses.replace(self, worker=index)

    def client(self, model: str) -> LLMClient:
        chosen = self.clients[model]
        return chosen[self.worker % len(chosen)] if isinstance(chosen, list) else chosen


class ClientError(RuntimeError):
    """A client failed with something other than an LLMError (gateway gone, bug)."""


class EpisodeClient:
    """Wraps a model client for one episode: adds the unit's sampling seed and, for offline test-double
    models, the expert plan from the *current* environment state to each request's hints."""

    def __init__(self, inner: LLMClient, env: Environment, *, sampling_seed: int, offline: bool) -> None:
        self.inner = inner
        self.env = env
        self.sampling_seed = sampling_seed
        self.offline = offline
        self.test_double = False
        self.models: set[str] = set()

    def complete(self, request: LLMRequest) -> LLMResponse:
        hints = dict(request.hints)
        hints["sampling_seed"] = self.sampling_seed
        if self.offline:
            hints["expert_plan"] = self.env.expert_plan()
        request = dataclasses.replace(request, hints=hints)
        try:
            response = self.inner.complete(request)
        except Exception as exc:
            if isinstance(exc, LLMError):
                raise
            raise ClientError(f"{type(exc).__name__}: {exc}") from exc
        self.test_double = self.test_double or response.test_double
        if response.model:
            self.models.add(response.model)
        return response


# --------------------------------------------------------------------------------------------
# forwarding records to the sink
# --------------------------------------------------------------------------------------------
class RecordForwarder:
    """Buffers an episode's records as rows and hands them to ``send`` in batches.

    ``send(rows_by_table)`` returns something to wait on (a Ray ObjectRef) or None; at most one
    batch is in flight, which bounds the worker's memory when the sink is slow.
    """

    def __init__(
        self,
        run_id: str,
        send: Callable[[dict[str, list[dict]]], Any],
        wait: Callable[[Any], Any],
        *,
        skip_calls: bool,
        batch_rows: int = 500,
    ) -> None:
        self.run_id = run_id
        self.send = send
        self.wait = wait
        self.skip_calls = skip_calls
        self.batch_rows = batch_rows
        self.buffer: dict[str, list[dict]] = {}
        self.n = 0
        self.sent = 0
        self._inflight: Any = None

    def __call__(self, record: Any) -> None:
        if self.skip_calls and isinstance(record, CallRecord):
            return
        # the agent's records (tree nodes, calls) meet the same vocabulary check as the driver's
        self.buffer.setdefault(type(record).table, []).append(record_to_row(check_vocabulary(record), self.run_id))
        self.n += 1
        if self.n >= self.batch_rows:
            self._ship()

    def _ship(self) -> None:
        if not self.n:
            return
        if self._inflight is not None:
            self.wait(self._inflight)
        batch, self.buffer, count = self.buffer, {}, self.n
        self.n = 0
        self._inflight = self.send(batch)
        self.sent += count

    def close(self) -> int:
        """Send what is left and wait until the sink holds every row; returns rows sent."""
        self._ship()
        if self._inflight is not None:
            self.wait(self._inflight)
            self._inflight = None
        return self.sent


# --------------------------------------------------------------------------------------------
# one unit
# --------------------------------------------------------------------------------------------
def _resident_bytes() -> int:
    try:
        with open(f"/proc/{os.getpid()}/status") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def agent_from_config(method: str, method_config: str) -> Agent:
    """The agent a unit's resolved settings describe (see :meth:`recap.config.AgentConfig.from_json`):
    the same config the driver hashed, field for field."""
    agent_cls, config_cls = methods.method_classes(method)
    config = config_cls.from_json(method_config)
    if config.to_json() != method_config:
        raise ConfigError(f"{method}: resolved settings do not round-trip (the unit was planned by another version)")
    return agent_cls(config)


class ReleaseChanged(RuntimeError):
    """The released text read now is not the one the unit was planned (and hashed) with."""


def release_demonstration(unit: UnitWork, agent: Agent) -> str | bool | ReleasePrompt:
    """What the episode pins first: True (the agent renders our demonstration) unless the unit's
    settings say ``prompts: release:<digest>``; then the authors' text for this instance, read from
    the release folder (:mod:`workers.release.texts`) and checked against the digest the unit's
    hash covers (ReleaseChanged otherwise): the released messages with their roles where
    :func:`workers.release.texts.release_prompt` builds them (the agent then leaves out our system
    text and rules), else the joined text. Plain strings either way: recap/ reads no file."""
    prompts = getattr(agent.config, "prompts", "ours")
    if not prompts.startswith("release:"):
        return True
    bench, split, task = place_of(unit.instance_id)
    folder = release_folder()
    think, name_only = getattr(agent.config, "think", "latest"), bool(getattr(agent.config, "name_only", False))
    text = release_text(folder, unit.method, bench, split, task, think=think, name_only=name_only)
    if f"release:{text.digest}" != prompts:
        raise ReleaseChanged(
            f"the released text for {unit.method} on {bench}/{split}/{task} changed since the plan "
            f"(sha256 {text.digest[:12]}..., planned {prompts[8:20]}...): re-run the sweep to plan it again"
        )
    structured = release_prompt(folder, unit.method, bench, split, task, think=think, name_only=name_only)
    return structured if structured is not None else text.text


class EpisodeRunner:
    """Plays units; the Ray actor is a thin shell around this (so it can be tested directly)."""

    def __init__(
        self,
        worker_id: str,
        run_id: str,
        factory: ClientFactory,
        send: Callable[[dict[str, list[dict]]], Any],
        wait: Callable[[Any], Any],
        *,
        batch_rows: int = 500,
    ) -> None:
        self.worker_id = worker_id
        self.run_id = run_id
        self.factory = factory
        self.send = send
        self.wait = wait
        self.batch_rows = batch_rows
        self._agents: dict[str, Agent] = {}
        self._clients: dict[str, LLMClient] = {}
        self.units_done = 0

    def _agent(self, unit: UnitWork) -> Agent:
        """The unit's agent, built from its resolved settings (cached per settings: an agent
        renders its demonstration once)."""
        key = unit.method_config + "|" + unit.method
        if key not in self._agents:
            self._agents[key] = agent_from_config(unit.method, unit.method_config)
        return self._agents[key]

    def _client(self, model_label: str) -> LLMClient:
        if model_label not in self._clients:
            self._clients[model_label] = self.factory.client(model_label)
        return self._clients[model_label]

    def run_unit(self, unit: UnitWork, attempt: int) -> EpisodeOutcome:
        """Play one attempt of a unit: an outcome with a result (the episode ended) or a crash
        (the agent or the model client broke; the driver retries it)."""
        episode_id = f"{unit.unit_id}-{attempt}"
        t0 = time.perf_counter()
        offline = unit.model.startswith(OFFLINE_PREFIX)
        out = EpisodeOutcome(
            unit_id=unit.unit_id,
            attempt=attempt,
            episode_id=episode_id,
            worker_id=self.worker_id,
            pid=os.getpid(),
            started_at=time.time(),
            env=EnvFacts(unit.benchmark),
            model=unit.model,
            test_double=offline,
        )
        forward = RecordForwarder(
            self.run_id, self.send, self.wait, skip_calls=bool(self.factory.writes_llm_calls), batch_rows=self.batch_rows
        )
        env: Environment | None = None
        try:
            agent = self._agent(unit)
            try:
                owner = registry.get_benchmark(unit.benchmark).owner_options(self.run_id, self.worker_id, episode_id)
                options = {**env_options_for(unit, agent), **owner}
                env = registry.make_env(unit.instance_id, step_multiplier=unit.step_multiplier, **options)
            except Exception as exc:  # missing data, broken game file: the attempt ends with env_error
                log.warning("%s: no environment for %s: %s: %s", episode_id, unit.instance_id, type(exc).__name__, exc)
                out.result = _env_error(exc)
                return out
            out.env = EnvFacts(
                benchmark=env.benchmark, split=env.split, task=env.task, optimal_steps=env.optimal_steps, max_steps=env.max_steps
            )
            try:
                demonstration = release_demonstration(unit, agent)
            except Exception as exc:  # the release folder went missing or changed since the plan
                log.warning("%s: %s", episode_id, exc)
                out.result = _env_error(exc)
                return out
            self._play(unit, agent, env, demonstration, out, forward, offline)
            return out
        finally:
            self._finish(out, env, forward, t0)

    def _play(
        self,
        unit: UnitWork,
        agent: Agent,
        env: Environment,
        demonstration: str | bool | ReleasePrompt,
        out: EpisodeOutcome,
        forward: RecordForwarder,
        offline: bool,
    ) -> None:
        """Run the agent's episode into ``out``: its result, or the crash of the agent or the model client."""
        episode_id = out.episode_id
        client = EpisodeClient(self._client(unit.model_label), env, sampling_seed=int(unit.sampling_seed), offline=offline)
        try:
            result = agent.run(env, client, episode_id=episode_id, emit=forward, demonstration=demonstration)
        except ClientError as exc:
            log.warning("%s: the model client failed: %s", episode_id, exc)
            out.crash = Crash("client", str(exc)[:2000])
            return
        except EnvError as exc:  # out of an agent that does not end its episode on one (not the shared runtime's)
            log.warning("%s: the environment failed: %s", episode_id, exc)
            out.result = _env_error(exc)
            return
        except Exception as exc:
            log.exception("%s: the agent crashed", episode_id)
            out.crash = Crash("agent", f"{type(exc).__name__}: {exc}"[:2000], traceback.format_exc()[-4000:])
            return
        out.result = result
        out.test_double = out.test_double or client.test_double
        if client.models:
            out.model = sorted(client.models)[0]

    def _finish(self, out: EpisodeOutcome, env: Environment | None, forward: RecordForwarder, t0: float) -> None:
        """However the attempt ended: close the environment, flush the records, stamp the times."""
        if env is not None:
            for record in env.take_records(out.episode_id, self.run_id):  # FEVER: the pages it read
                forward(record)
            try:
                env.close()
            except Exception:
                pass
        out.rows_sent = forward.close()
        out.ended_at = time.time()
        out.wall_s = time.perf_counter() - t0
        self.units_done += 1
        log.debug(
            "%s done in %.2fs: %s", out.episode_id, out.wall_s, out.result.end_reason if out.result is not None else "no result"
        )


def _env_error(exc: Exception) -> EpisodeResult:
    """The result of an attempt whose environment (or released text) could not be had, or that an
    environment failure ended outside the agent's own handling (no partial counts then). An
    :class:`recap.env.EnvError` with a kind (``sandbox``: the container service failed) writes
    that kind first, so the row is read as what it is (infrastructure, run again by resume)."""
    if isinstance(exc, EnvError) and exc.kind:
        return EpisodeResult(exc.end_reason, False, 0, 0, error=exc.row_error()[:2000])
    return EpisodeResult("env_error", False, 0, 0, error=f"{type(exc).__name__}: {exc}"[:2000])


# --------------------------------------------------------------------------------------------
# the Ray actor
# --------------------------------------------------------------------------------------------
class _EpisodeWorker:
    """One episode worker process: its own slot ``worker_id`` and, when the pool puts several
    episodes in one process (``ray.episodes_per_process``), more slots named by the driver at
    their first unit. Each slot has its own :class:`EpisodeRunner` (its agents, its clients'
    cache) and plays one unit at a time; Ray runs the slots' ``run_unit`` calls on threads of
    this process at once (the actor's ``max_concurrency``), so episodes share nothing but the
    process: each builds its own environment and uses its own agent."""

    def __init__(self, worker_id: str, run_id: str, sink: Any, factory: ClientFactory, batch_rows: int = 500) -> None:
        import ray  # Ray only inside the actor: the rest of the module runs without a cluster

        configure_from_env()

        self._sink = sink
        self._make = lambda wid: EpisodeRunner(
            wid,
            run_id,
            factory,
            send=lambda rows: sink.add.remote(rows),
            wait=lambda ref: ray.get(ref),
            batch_rows=batch_rows,
        )
        self.runner = self._make(worker_id)
        self.runners: dict[str, EpisodeRunner] = {worker_id: self.runner}
        self._lock = threading.Lock()

    def pid(self) -> int:
        return os.getpid()

    def ping(self) -> str:
        return self.runner.worker_id

    def node(self) -> str:
        import ray  # Ray only inside the actor (module docstring)

        return ray.get_runtime_context().get_node_id()

    def memory(self) -> int:
        """Resident set size of this worker process, in bytes."""
        return _resident_bytes()

    def _runner(self, slot: str | None) -> EpisodeRunner:
        if slot is None:
            return self.runner
        with self._lock:  # slots start on different threads
            if slot not in self.runners:
                self.runners[slot] = self._make(slot)
            return self.runners[slot]

    def run_unit(self, unit: UnitWork, attempt: int, slot: str | None = None) -> EpisodeOutcome:
        """Play one attempt on slot ``slot`` (None: this process's own)."""
        return self._runner(slot).run_unit(unit, attempt)


def worker_actor(
    num_cpus: float = 0.05, spread: bool = False, runtime_env: dict | None = None, resources: dict[str, float] | None = None
) -> Any:
    """The Ray actor class with the given resource shape.

    ``max_restarts=0``: the driver replaces dead workers itself, so that it can count attempts
    and record the loss. ``max_concurrency`` > 1 so that ``pid``/``memory`` answer while a unit
    runs; the driver never sends a slot two units at once, and raises it (``.options``) for an
    actor that hosts several slots (:class:`pipeline.worker_pool.RayWorkerPool`)."""
    import ray  # Ray only here and in the actor (module docstring)

    options: dict[str, Any] = {"num_cpus": num_cpus, "max_restarts": 0, "max_concurrency": 4}
    if spread:
        options["scheduling_strategy"] = "SPREAD"
    if runtime_env:
        options["runtime_env"] = runtime_env
    if resources:  # a coding sweep's sandbox slot on its node (ray.sandboxes_per_node)
        options["resources"] = resources
    return ray.remote(**options)(_EpisodeWorker)
