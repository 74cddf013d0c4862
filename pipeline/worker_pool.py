"""Where attempts run: a pool of episode workers behind one small interface.

Why an interface: the session (:mod:`pipeline.driver`) decides *what* runs - which unit, which
attempt, when to retry or give up - and must not care *where*. Two pools implement it:

* :class:`RayWorkerPool` - episode workers in Ray actors (the production path): one per
  process, or several per process when many are in flight (``ray.episodes_per_process``: a
  Ray worker process alone costs ~50 MB, so hundreds of episodes in flight share fewer
  processes, each episode on its own thread with its own environment and agent); a worker
  process that dies is told apart from a task that failed on another actor, and replaced;
* :class:`InProcessWorkerPool` - threads in the driver's process, each with its own
  :class:`workers.episode_worker.EpisodeRunner`: no actor start-up, breakpoints work, and the
  session logic is testable without a cluster. Its workers cannot die on their own.

Both hand back :class:`Finished` records: the attempt's typed outcome, or why it has none.
"""

from __future__ import annotations

import concurrent.futures as cf
import itertools
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

from pipeline.errors import PipelineError
from pipeline.resume import Pending
from schemas.outcomes import EpisodeOutcome

log = logging.getLogger(__name__)

#: why an attempt has no outcome: its worker process died (``worker_lost``), its task raised
#: (``task_raised``), or it failed on another actor while the worker lived (``elsewhere``:
#: the session asks the sink channel whether the sink is the one gone)
FailureKind = Literal["worker_lost", "task_raised", "elsewhere"]


@dataclass
class Slot:
    """One worker: its id, its handle (an actor, or the in-process runner) and units played.

    ``host`` is the id of the process that hosts it in a Ray pool (the first worker id of that
    actor); several slots share a host, and its handle, when a process plays several episodes
    at once."""

    worker_id: str
    handle: Any
    units: int = 0
    host: str = ""


#: episode processes per CPU of the cluster before ``episodes_per_process`` "auto" puts several
#: episodes in one process: up to this many processes per CPU a sweep keeps one episode per process
PROCESSES_PER_CPU = 4


def episodes_per_process(workers: int, cpus: float, asked: int | None) -> int:
    """How many episodes one worker process hosts at once: what the sweep asked for
    (``ray.episodes_per_process``), else (None, "auto") one while the workers fit in
    :data:`PROCESSES_PER_CPU` processes per CPU, and beyond that as many as spread the
    workers over that many processes (2 CPUs: 8 workers one each, 32 four, 256 thirty-two).

    Why: a Ray worker process costs ~50 MB before it plays anything, so 256 episodes in 256
    processes need 13+ GB; the episodes spend their time waiting on the model, and a few
    processes per CPU keep the CPUs as busy as hundreds would."""
    if asked is not None:
        return max(1, asked)
    processes = max(1, int(max(cpus, 1) * PROCESSES_PER_CPU))
    return max(1, -(-workers // processes))


@dataclass
class Finished:
    """An attempt that came back: its outcome, or the failure that left it without one."""

    slot: Slot
    pending: Pending
    started: float
    outcome: EpisodeOutcome | None = None
    failure: FailureKind | None = None
    error: str = ""
    #: the key the pool knew the attempt by (for :meth:`WorkerPool.restore`)
    key: Any = field(default=None, repr=False)


class WorkerPool(Protocol):
    """What the session needs from wherever attempts run."""

    def start(self, n: int) -> dict[str, str]:
        """Start ``n`` workers; worker id -> node id."""

    def has_idle(self) -> bool: ...

    def submit(self, pending: Pending) -> Slot:
        """Start an attempt on an idle worker (the caller checked :meth:`has_idle`)."""

    def in_flight(self) -> int: ...

    def wait(self, timeout: float) -> list[Any]:
        """Keys of attempts that came back (at most ``timeout`` seconds for the first)."""

    def collect(self, key: Any) -> Finished:
        """The attempt behind ``key``; its worker is idle again unless it died (then replaced
        only by :meth:`add_worker`) or the failure is ``elsewhere`` (then :meth:`release` or
        :meth:`restore` decides)."""

    def release(self, fin: Finished) -> None:
        """The worker of an ``elsewhere`` failure takes work again."""

    def restore(self, fin: Finished) -> None:
        """Put an attempt back in flight (the session stops; it counts as cut, not failed)."""

    def add_worker(self) -> Slot:
        """A new idle worker (after one was lost)."""

    def shutdown(self) -> None: ...


class _SlotBook:
    """What both pools keep alike: the workers (slots), the idle ones, and the attempts in
    flight by their wait key; each pool adds how a worker is made and how an attempt runs."""

    def __init__(self, session: str, prefix: str) -> None:
        self.session = session
        self.slots: list[Slot] = []
        self.idle: list[Slot] = []
        self._inflight: dict[Any, tuple[Slot, Pending, float]] = {}
        self._prefix = prefix
        self._seq = itertools.count(1)

    def _next_id(self) -> str:
        return f"{self.session}-{self._prefix}{next(self._seq):03d}"

    def _new_slot(self) -> Slot:
        raise NotImplementedError

    def has_idle(self) -> bool:
        """Whether a worker waits for an attempt."""
        return bool(self.idle)

    def in_flight(self) -> int:
        """Attempts handed out and not yet collected."""
        return len(self._inflight)

    def release(self, fin: Finished) -> None:
        """Return a finished attempt's worker to the idle ones."""
        self.idle.append(fin.slot)

    def restore(self, fin: Finished) -> None:
        """Put a collected attempt back in flight (its result is read again later)."""
        self._inflight[fin.key] = (fin.slot, fin.pending, fin.started)

    def add_worker(self) -> Slot:
        """A new idle worker (replacing one that died)."""
        slot = self._new_slot()
        self.slots.append(slot)
        self.idle.append(slot)
        return slot


@dataclass
class _Host:
    """One episode worker process (a Ray actor) and the slots it plays: at most ``capacity`` at once."""

    host_id: str
    handle: Any
    capacity: int
    slots: list[Slot] = field(default_factory=list)
    dead: bool = False


class RayWorkerPool(_SlotBook):
    """Episode workers as Ray actors (:func:`workers.episode_worker.worker_actor`), ``per_process``
    slots to an actor: each slot is a worker to the session (one attempt at a time, its own id,
    environment and agent), the actor plays its slots' attempts on threads at once.

    A process that dies takes every slot it hosted: each attempt it had in flight comes back
    ``worker_lost`` (the session retries each and asks :meth:`add_worker` for one worker per
    attempt lost); its idle slots go with it and are replaced here at once, so the pool keeps
    its size. New slots fill the room left on living processes before a new process starts."""

    def __init__(self, worker_cls: Any, run_id: str, sink: Any, factory: Any, *, session: str, per_process: int = 1) -> None:
        super().__init__(session, "w")
        self.worker_cls = worker_cls
        self.run_id = run_id
        self.sink = sink
        self.factory = factory
        self.per_process = max(1, per_process)
        self.hosts: dict[str, _Host] = {}
        self._made = itertools.count()

    def _start_host(self, host_id: str) -> _Host:
        cls = self.worker_cls
        if self.per_process > 1:  # one thread per slot, and room for pid/memory/node while they run
            cls = cls.options(max_concurrency=self.per_process + 3)
        factory = self._factory_for(next(self._made))
        host = _Host(host_id, cls.remote(host_id, self.run_id, self.sink, factory), self.per_process)
        self.hosts[host_id] = host
        return host

    def _new_slot(self) -> Slot:
        wid = self._next_id()
        host = next((h for h in self.hosts.values() if not h.dead and len(h.slots) < h.capacity), None)
        if host is None:
            host = self._start_host(wid)
        slot = Slot(wid, host.handle, host=host.host_id)
        host.slots.append(slot)
        return slot

    def _factory_for(self, index: int) -> Any:
        """The client factory of the ``index``-th worker process started: a factory that spreads
        workers over gateway shards (``for_worker``, round robin by process) gives each its own;
        others are shared. The slots of one process share its shard."""
        for_worker = getattr(self.factory, "for_worker", None)
        return for_worker(index) if for_worker is not None else self.factory

    def start(self, n: int) -> dict[str, str]:
        """Start ``n`` workers (``ceil(n / per_process)`` actors) and wait (up to 300 s) until each actor
        reports its node; PipelineError when they cannot start."""
        import ray  # lazy: Ray loads only where a session uses it

        self.slots = [self._new_slot() for _ in range(n)]
        hosts = list(dict.fromkeys(s.host for s in self.slots))
        try:
            nodes = dict(zip(hosts, ray.get([self.hosts[h].handle.node.remote() for h in hosts], timeout=300)))
        except Exception as exc:
            raise PipelineError(f"episode workers failed to start: {str(exc).splitlines()[0]}") from None
        self.idle = list(self.slots)
        return {s.worker_id: nodes[s.host] for s in self.slots}

    def submit(self, pending: Pending) -> Slot:
        slot = self.idle.pop()
        work = pending.unit.work()
        if slot.worker_id == slot.host:  # the actor's own slot
            ref = slot.handle.run_unit.remote(work, pending.attempt)
        else:
            ref = slot.handle.run_unit.remote(work, pending.attempt, slot.worker_id)
        log.debug("unit %s attempt %d -> worker %s", pending.unit.unit_id, pending.attempt, slot.worker_id)
        self._inflight[ref] = (slot, pending, time.time())
        return slot

    def wait(self, timeout: float) -> list[Any]:
        """Every attempt that is ready once the first one is (at most ``timeout`` seconds), so a burst is
        collected in one round."""
        import ray  # lazy: Ray loads only where a session uses it

        if not self._inflight:
            return []
        ready, _ = ray.wait(list(self._inflight), num_returns=1, timeout=timeout)
        if ready:
            ready, _ = ray.wait(list(self._inflight), num_returns=len(self._inflight), timeout=0)
        return ready

    @staticmethod
    def _worker_died(exc: BaseException, slot: Slot) -> bool:
        """The worker process itself is gone (not: its task failed on another actor)."""
        from ray.exceptions import RayTaskError  # lazy: Ray loads only where a session uses it

        if isinstance(exc, RayTaskError):  # its task raised: the worker lived to report it
            return False
        dead = getattr(exc, "actor_id", None)
        try:
            mine = slot.handle._actor_id.hex()
        except Exception:
            mine = None
        return not (dead and mine and dead != mine)

    def _host_lost(self, host: _Host) -> None:
        """A worker process died: kill what is left of it, drop every slot it hosted, and replace
        those that were idle (the session replaces the others, one per attempt lost)."""
        import ray  # lazy: Ray loads only where a session uses it

        host.dead = True
        try:
            ray.kill(host.handle)
        except Exception:
            pass
        idle = [s for s in host.slots if s in self.idle]
        self.idle = [s for s in self.idle if s.host != host.host_id]
        self.slots = [s for s in self.slots if s.host != host.host_id]
        for _ in idle:
            self.add_worker()

    def _idle_again(self, slot: Slot) -> None:
        """A slot whose attempt came back takes work again, or, its process gone meanwhile (a
        sibling slot's attempt saw it die), is replaced by a new one."""
        host = self.hosts.get(slot.host)
        if host is not None and host.dead:
            self.add_worker()
        else:
            self.idle.append(slot)

    def release(self, fin: Finished) -> None:
        """Return a finished attempt's worker to the idle ones (a new one if its process died)."""
        self._idle_again(fin.slot)

    def collect(self, key: Any) -> Finished:
        """The attempt behind ``key``: an actor error is ``worker_lost`` only when that actor is dead (it is
        killed and its slots dropped from the pool), else ``elsewhere``; a task that raised is ``task_raised``
        and its worker stays."""
        import ray  # lazy: Ray loads only where a session uses it
        from ray.exceptions import ActorDiedError, ActorUnavailableError, RayActorError, RayTaskError, WorkerCrashedError

        slot, pending, started = self._inflight.pop(key)
        fin = Finished(slot, pending, started, key=key)
        try:
            fin.outcome = ray.get(key)
        except (RayActorError, ActorDiedError, ActorUnavailableError, WorkerCrashedError) as exc:
            fin.error = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
            if not self._worker_died(exc, slot):
                fin.failure = "elsewhere"
                return fin
            fin.failure = "worker_lost"
            log.warning(
                "worker %s died running unit %s attempt %d: %s", slot.worker_id, pending.unit.unit_id, pending.attempt, fin.error
            )
            host = self.hosts.get(slot.host)
            if host is not None and not host.dead:
                self._host_lost(host)
            return fin
        except RayTaskError as exc:
            fin.failure, fin.error = "task_raised", str(exc).splitlines()[-1][:1000]
            log.warning(
                "unit %s attempt %d raised in worker %s: %s", pending.unit.unit_id, pending.attempt, slot.worker_id, fin.error
            )
            self._idle_again(slot)
            return fin
        slot.units += 1
        self._idle_again(slot)
        return fin

    def shutdown(self) -> None:
        """Kill every actor (errors ignored: an actor may already be gone)."""
        import ray  # lazy: Ray loads only where a session uses it

        for host in self.hosts.values():
            try:
                ray.kill(host.handle)
            except Exception:
                pass
        self.idle = []


class InProcessWorkerPool(_SlotBook):
    """Episode runners on threads of the driver's process.

    ``make_runner(worker_id)`` builds a :class:`workers.episode_worker.EpisodeRunner` (with the
    run's model-client factory and a way to send rows to the sink). Each thread owns one
    runner, so an agent's state is never shared between threads."""

    def __init__(self, make_runner: Callable[[str], Any], *, session: str) -> None:
        super().__init__(session, "t")
        self.make_runner = make_runner
        self._executor: cf.ThreadPoolExecutor | None = None

    def _new_slot(self) -> Slot:
        wid = self._next_id()
        return Slot(wid, self.make_runner(wid))

    def start(self, n: int) -> dict[str, str]:
        """Start a thread pool of ``n`` runners; every worker reports node "local"."""
        self._executor = cf.ThreadPoolExecutor(max_workers=max(1, n), thread_name_prefix="episode")
        self.slots = [self._new_slot() for _ in range(n)]
        self.idle = list(self.slots)
        return {s.worker_id: "local" for s in self.slots}

    def submit(self, pending: Pending) -> Slot:
        assert self._executor is not None, "start() first"
        slot = self.idle.pop()
        fut = self._executor.submit(slot.handle.run_unit, pending.unit.work(), pending.attempt)
        self._inflight[fut] = (slot, pending, time.time())
        return slot

    def wait(self, timeout: float) -> list[Any]:
        if not self._inflight:
            return []
        done, _ = cf.wait(list(self._inflight), timeout=timeout, return_when=cf.FIRST_COMPLETED)
        return [f for f in self._inflight if f.done()] if done else []

    def collect(self, key: Any) -> Finished:
        """The attempt behind ``key``: a runner that raised is ``task_raised``; a thread never dies, so the
        worker is always idle again."""
        slot, pending, started = self._inflight.pop(key)
        fin = Finished(slot, pending, started, key=key)
        exc = key.exception()
        if exc is not None:  # the runner itself raised (it catches the agent's and client's errors)
            fin.failure, fin.error = "task_raised", f"{type(exc).__name__}: {exc}"[:1000]
        else:
            fin.outcome = key.result()
            slot.units += 1
        self.idle.append(slot)
        return fin

    def shutdown(self) -> None:
        """Stop the threads without waiting: queued attempts are cancelled, a running one finishes unseen."""
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
        self.idle = []
