"""Where attempts run: a pool of episode workers behind one small interface.

Why an interface: the session (:mod:`pipeline.driver`) decides *what* runs - which unit, which
attempt, when to retry or give up - and must not care *where*. Two pools implement it:

* :class:`RayWorkerPool` - one Ray actor per worker (the production path): a worker process
  that dies is told apart from a task that failed on another actor, and replaced;
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
    """One worker: its id, its handle (an actor, or the in-process runner) and units played."""

    worker_id: str
    handle: Any
    units: int = 0


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


class RayWorkerPool(_SlotBook):
    """Episode workers as Ray actors (:func:`workers.episode_worker.worker_actor`)."""

    def __init__(self, worker_cls: Any, run_id: str, sink: Any, factory: Any, *, session: str) -> None:
        super().__init__(session, "w")
        self.worker_cls = worker_cls
        self.run_id = run_id
        self.sink = sink
        self.factory = factory
        self._made = itertools.count()

    def _new_slot(self) -> Slot:
        wid = self._next_id()
        return Slot(wid, self.worker_cls.remote(wid, self.run_id, self.sink, self._factory_for(next(self._made))))

    def _factory_for(self, index: int) -> Any:
        """The client factory of the ``index``-th worker started: a factory that spreads workers
        over gateway shards (``for_worker``, round robin) gives each its own; others are shared."""
        for_worker = getattr(self.factory, "for_worker", None)
        return for_worker(index) if for_worker is not None else self.factory

    def start(self, n: int) -> dict[str, str]:
        """Start ``n`` actors and wait (up to 300 s) until each reports its node; PipelineError when they cannot start."""
        import ray  # lazy: Ray loads only where a session uses it

        self.slots = [self._new_slot() for _ in range(n)]
        try:
            nodes = ray.get([s.handle.node.remote() for s in self.slots], timeout=300)
        except Exception as exc:
            raise PipelineError(f"episode workers failed to start: {str(exc).splitlines()[0]}") from None
        self.idle = list(self.slots)
        return {s.worker_id: node for s, node in zip(self.slots, nodes)}

    def submit(self, pending: Pending) -> Slot:
        slot = self.idle.pop()
        ref = slot.handle.run_unit.remote(pending.unit.work(), pending.attempt)
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

    def collect(self, key: Any) -> Finished:
        """The attempt behind ``key``: an actor error is ``worker_lost`` only when that actor is dead (it is
        killed and dropped from the pool), else ``elsewhere``; a task that raised is ``task_raised`` and its
        worker stays."""
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
            try:
                ray.kill(slot.handle)
            except Exception:
                pass
            self.slots.remove(slot)
            return fin
        except RayTaskError as exc:
            fin.failure, fin.error = "task_raised", str(exc).splitlines()[-1][:1000]
            log.warning(
                "unit %s attempt %d raised in worker %s: %s", pending.unit.unit_id, pending.attempt, slot.worker_id, fin.error
            )
            self.idle.append(slot)
            return fin
        slot.units += 1
        self.idle.append(slot)
        return fin

    def shutdown(self) -> None:
        """Kill every actor (errors ignored: an actor may already be gone)."""
        import ray  # lazy: Ray loads only where a session uses it

        for slot in self.slots:
            try:
                ray.kill(slot.handle)
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
