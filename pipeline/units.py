"""Units of work: (environment instance, method + settings, model + params, sampling seed).

Each unit has a stable content hash, ``unit_id``: the hash of everything that can change what an
episode *does* — the instance, the method name and its fully resolved settings (profile,
ablation, per-episode limits included), the model string and its params, the sampling seed and the step
multiplier, and the environment options that change what an episode does (each benchmark declares
its options' kinds, :mod:`workers.envs.options`; only those away from their declared default enter,
so the units of a sweep that sets none keep the ids they always had). Transport settings (retries, rpm/tpm, concurrency, worker counts, caps, prices,
API base and key) and the environment options that only change how an episode is run (data
folders, request rates) are left out, so raising a rate limit or a cap never invalidates finished
work. A unit's *key* (instance, method label, model label, sampling seed) is its human identity: a key
whose hash changed between two versions of a sweep file is a *changed* unit.
"""

from __future__ import annotations

import hashlib
import json
import random
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Any

from pipeline.errors import SpecError
from pipeline.spec import EnvSpec, SweepSpec
from recap import methods
from recap.config import ConfigError
from recap.env import DataNotFoundError, EnvError, UnknownInstanceError
from schemas.labels import ablation_of_config
from schemas.outcomes import UnitWork
from workers.envs.options import identity_options, undeclared_problem
from workers.envs.registry import Benchmark, get_benchmark, place_of, split_id
from workers.episode_worker import build_agent
from workers.llm.offline.knobs import hashed_options
from workers.release.texts import ReleaseMissing, ReleaseUnavailable, release_folder, release_text

HASH_VERSION = 1


def _canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)


@dataclass(frozen=True, eq=False)
class Unit:
    """One unit of work: one episode to play (instance, method with resolved settings, model with params, sampling seed).
    ``unit_id`` is the content hash of :func:`unit_hash`; ``method_label``/``model_label`` are the spec's
    names for the arm, ``method``/``model`` what actually runs."""

    unit_id: str
    instance_id: str
    method_label: str
    method: str
    profile: str | None
    ablation: str | None
    settings: Mapping[str, Any]
    method_config: str
    model_label: str
    model: str
    model_params: Mapping[str, Any]
    sampling_seed: int
    step_multiplier: float
    env_options: Mapping[str, Any] = field(default_factory=dict)
    #: the part of ``env_options`` in the unit id (:func:`workers.envs.options.identity_options`)
    id_options: Mapping[str, Any] = field(default_factory=dict)
    #: the id without ``id_options`` (the only id before environment options were hashed)
    plain_id: str = ""
    #: ``unit_id`` is ``plain_id`` although ``id_options`` is not empty: kept for a run written
    #: before options were hashed, whose episodes ran with these options (:func:`keep_earlier_ids`)
    earlier_id: bool = False

    @property
    def benchmark(self) -> str:
        """The benchmark name: the instance id up to its first ``/``."""
        return self.instance_id.split("/", 1)[0]

    @property
    def recorded_config(self) -> str:
        """The settings its episode rows record: ``method_config`` as the episode applies it
        (:meth:`recap.config.AgentConfig.recorded_json`: the window applied, null for none)."""
        return recorded_config(self.method, self.method_config)

    @property
    def ablation_name(self) -> str | None:
        """The ablation the episode rows name (:func:`resolve_ablation`)."""
        return resolve_ablation(self.ablation, self.method_config)

    @property
    def key(self) -> str:
        """The unit's human identity (instance, method label, model label, sampling seed); stable across spec
        edits, unlike ``unit_id``. Its text (``... | seed N``) is kept as plan.json has always stored it: a
        resume matches the stored keys (:func:`diff_plans`)."""
        return f"{self.instance_id} | {self.method_label} | {self.model_label} | seed {self.sampling_seed}"

    def work(self) -> UnitWork:
        """What a worker needs to play the unit: the resolved settings, not the raw ones."""
        return UnitWork(
            unit_id=self.unit_id,
            instance_id=self.instance_id,
            method=self.method,
            method_config=self.method_config,
            model_label=self.model_label,
            model=self.model,
            sampling_seed=self.sampling_seed,
            step_multiplier=self.step_multiplier,
            env_options=tuple(sorted(self.env_options.items())),
        )

    def summary(self) -> dict[str, Any]:
        """What plan.json keeps per unit (enough for status, the report's coverage table and
        diffs without the benchmarks). ``method`` is the arm's label there (as in every
        plan.json so far: status groups by it), ``method_name`` the method itself; the place
        (benchmark, split, task) is the one its episode rows will have."""
        bench, split, task = place_of(self.instance_id)
        return {
            "unit_id": self.unit_id,
            "key": self.key,
            "instance_id": self.instance_id,
            "method": self.method_label,
            "model": self.model_label,
            "sampling_seed": self.sampling_seed,
            "method_name": self.method,
            "profile": self.profile,
            "ablation": self.ablation_name,
            "provider_model": self.model,
            "benchmark": bench,
            "split": split,
            "task": task,
            "env_options": dict(self.id_options),
            **({"earlier_id": True} if self.earlier_id else {}),
        }


@lru_cache(maxsize=256)
def recorded_config(method: str, method_config: str) -> str:
    """:meth:`recap.config.AgentConfig.recorded_json` of a unit's resolved settings; the settings
    as given when this process cannot read them (a method registered elsewhere)."""
    try:
        _, config_cls = methods.method_classes(method)
        return config_cls.from_json(method_config).recorded_json()
    except (ConfigError, KeyError, TypeError, ValueError):
        return method_config


def resolve_ablation(ablation: str | None, method_config: str) -> str | None:
    """The ablation an arm's episode rows name: the sweep's ``ablation`` when it names one
    (``no_think``, ``level_3`` ...; ``original`` is none), else what its settings amount to
    (``settings: {think: none}`` is ``no_think``; :func:`schemas.labels.ablation_of_config`),
    None for the original method. The context window is not an ablation: reports tell window
    variants apart by ``method_config.window``."""
    if ablation is not None:
        return None if ablation == "original" else ablation
    return ablation_of_config(method_config)


def unit_hash(
    *,
    instance_id: str,
    method: str,
    method_config: str,
    model: str,
    params: Mapping[str, Any],
    sampling_seed: int,
    step_multiplier: float,
    env_options: Mapping[str, Any] | None = None,
) -> str:
    """The ``unit_id``: 16 hex digits of a sha256 over what changes what an episode does (see the module
    docstring); ``HASH_VERSION`` is inside, so a new hashing never collides with an old one. The sampling
    seed is hashed under its old name ``seed``: unit ids stay those of runs written before the rename.
    ``env_options`` (the environment options in the id, :func:`workers.envs.options.identity_options`)
    is hashed under ``env`` only when there are any: the units of a sweep that sets none keep the ids
    of runs written before options were hashed."""
    content = {
        "v": HASH_VERSION,
        "instance": instance_id,
        "method": method,
        "config": json.loads(method_config),
        "model": model,
        "params": dict(params),
        "seed": sampling_seed,
        "step_multiplier": float(step_multiplier),
    }
    if env_options:
        content["env"] = dict(env_options)
    return hashlib.sha256(_canonical(content).encode()).hexdigest()[:16]


#: most units one sweep may expand to (a typo in sampling_seeds or a selector must not exhaust memory);
#: split larger sweeps into several runs
MAX_UNITS = 200_000


def canonical_instance_id(instance_id: str, env: Any = None) -> str:
    """The one spelling of an instance id, so that two spellings of one instance
    (``blocksworld/3@01`` and ``blocksworld/3@1``, ``robotouille/...@042`` and ``...@42``) name
    one unit: the id the benchmark's environment reports for itself (``env.instance_id``) when it
    is one of that benchmark's, else the benchmark's own spelling
    (:meth:`workers.envs.registry.Benchmark.canonical_id`: Blocksworld drops leading zeros); an
    id of a benchmark not registered here as written."""
    bench = instance_id.partition("/")[0]
    try:
        found: Benchmark | None = get_benchmark(bench)
    except (UnknownInstanceError, ImportError):
        found = None
    if found is not None:
        instance_id = found.canonical_id(instance_id)
    own = getattr(env, "instance_id", None)
    if isinstance(own, str) and own.startswith(bench + "/") and len(own) > len(bench) + 1:
        return own
    return instance_id


# --------------------------------------------------------------------------------------------
def resolve_instances(envs: Sequence[EnvSpec]) -> list[tuple[str, dict[str, Any]]]:
    """Instance ids (with their env options) in spec order, deduplicated; errors name the entry."""
    out: list[tuple[str, dict[str, Any]]] = []
    seen: set[str] = set()
    for i, env in enumerate(envs):
        where = f"environments[{i}]"
        try:
            bench = get_benchmark(env.benchmark)
        except UnknownInstanceError as exc:
            raise SpecError(f"{where}: {exc}") from None
        except (ImportError, AttributeError) as exc:
            raise SpecError(f"{where}: benchmark {env.benchmark!r} is not available here ({exc})") from None
        problem = undeclared_problem(env.benchmark, bench.declared_options(), env.options)
        if problem is not None:
            raise SpecError(f"{where}: {problem}")
        ids: list[str] = []
        for sel in env.tasks:
            try:
                found = list(bench.list_instances_for(sel, env.options))
            except (UnknownInstanceError, DataNotFoundError, EnvError, ValueError) as exc:
                raise SpecError(f"{where}: {env.benchmark} task {sel!r}: {exc}") from None
            if not found:
                raise SpecError(f"{where}: {env.benchmark} task {sel!r} matches no instance")
            ids += found[: env.limit] if env.limit else found
        for inst in env.instances:
            try:
                b, _ = split_id(inst)
                if b != env.benchmark:
                    raise UnknownInstanceError(f"instance {inst!r} is not a {env.benchmark} instance")
                canon = canonical_instance_id(inst)
                made = bench.make(canon, **env.options)
                try:
                    canon = canonical_instance_id(canon, made)
                finally:
                    made.close()
            except (UnknownInstanceError, DataNotFoundError, EnvError, ValueError, TypeError, OSError) as exc:
                raise SpecError(f"{where}: {exc}") from None
            ids.append(canon)
        for inst in ids:
            if inst not in seen:
                seen.add(inst)
                out.append((inst, dict(env.options)))
    return out


def resolve_methods(spec: SweepSpec, benchmark: str | None = None) -> list[tuple[Any, dict[str, Any], str]]:
    """(method spec, effective settings, canonical config JSON) per method, as the method runs
    on ``benchmark`` (profiles can differ per benchmark); errors name the method."""
    limits = spec.limits.agent_settings()
    out = []
    for i, m in enumerate(spec.methods):
        settings = {**limits, **m.settings}
        try:
            extra = {"prompts": "release"} if m.prompts == "release" else {}
            agent = build_agent(
                m.method, profile=m.profile, ablation=m.ablation, settings={**settings, **extra}, benchmark=benchmark
            )
        except ConfigError as exc:
            raise SpecError(f"methods[{i}] ({m.name}): {exc}") from None
        except TypeError as exc:
            raise SpecError(f"methods[{i}] ({m.name}): {exc}") from None
        out.append((m, settings, agent.config.to_json()))
    return out


@dataclass
class Plan:
    """A sweep expanded into its units, in the fixed order of :func:`expand`."""

    spec: SweepSpec
    units: list[Unit]

    def by_id(self) -> dict[str, Unit]:
        """The units keyed by ``unit_id``."""
        return {u.unit_id: u for u in self.units}

    def to_json(self) -> str:
        """The plan.json text: the hash version and each unit's :meth:`Unit.summary`."""
        return json.dumps({"hash_version": HASH_VERSION, "units": [u.summary() for u in self.units]}, indent=1)


def expand(spec: SweepSpec) -> Plan:
    """All units of a sweep, in a fixed order (instances, then methods, models, sampling seeds)."""
    instances = resolve_instances(spec.environments)
    n = len(instances) * len(spec.methods) * len(spec.models) * len(spec.sampling_seeds)
    if n > MAX_UNITS:
        raise SpecError(
            f"the sweep expands to {n:,} units ({len(instances)} instances x {len(spec.methods)} methods x "
            f"{len(spec.models)} models x {len(spec.sampling_seeds)} sampling seeds); at most {MAX_UNITS:,} per run: split it"
        )
    methods_by_benchmark: dict[str, list[tuple[Any, dict[str, Any], str]]] = {}
    units: list[Unit] = []
    seen: dict[str, str] = {}
    release: dict[tuple[str, str, str], str] = {}
    benchmarks = {inst.split("/", 1)[0] for inst, _ in instances}
    multipliers = [method_step_multipliers(spec, i, benchmarks) for i in range(len(spec.methods))]
    for inst, options in instances:
        benchmark = inst.split("/", 1)[0]
        if benchmark not in methods_by_benchmark:
            methods_by_benchmark[benchmark] = resolve_methods(spec, benchmark)
        id_options = identity_options(get_benchmark(benchmark).declared_options(), options)
        for i, (m, settings, resolved) in enumerate(methods_by_benchmark[benchmark]):
            cfg = with_release_digest(spec, m, inst, resolved, release) if m.prompts == "release" else resolved
            multiplier = step_multiplier_for(spec, i, inst, multipliers[i])
            for model in spec.models:
                for sampling_seed in spec.sampling_seeds:
                    keys = dict(
                        instance_id=inst,
                        method=m.method,
                        method_config=cfg,
                        model=model.model,
                        params={**model.params, **({"options": hashed_options(model.options)} if model.options else {})},
                        sampling_seed=sampling_seed,
                        step_multiplier=multiplier,
                    )
                    uid = unit_hash(**keys, env_options=id_options)
                    plain = uid if not id_options else unit_hash(**keys)
                    u = Unit(
                        uid,
                        inst,
                        m.name,
                        m.method,
                        m.profile,
                        m.ablation,
                        settings,
                        cfg,
                        model.name,
                        model.model,
                        dict(model.params),
                        sampling_seed,
                        multiplier,
                        options,
                        id_options,
                        plain,
                    )
                    if uid in seen:
                        raise SpecError(
                            f"units {seen[uid]!r} and {u.key!r} are identical (same method settings and model); remove one"
                        )
                    seen[uid] = u.key
                    units.append(u)
    return Plan(spec, units)


#: one resolved ``step_multipliers`` entry of a method: (key, the instance ids it covers, multiplier)
TaskMultiplier = tuple[str, frozenset[str], float]


def method_step_multipliers(spec: SweepSpec, index: int, benchmarks: set[str]) -> list[TaskMultiplier]:
    """The ``step_multipliers`` of ``spec.methods[index]`` resolved to instance ids: each key's
    benchmark must exist and its selector must be one the benchmark knows (a typo is refused, not
    silently run at the default cap). A key for a benchmark the sweep does not run is still
    checked when its instance list can be read without data, else left out."""
    m = spec.methods[index]
    where = f"methods[{index}] ({m.name}): step_multipliers"
    out: list[TaskMultiplier] = []
    for key, value in m.step_multipliers.items():
        bench_name, _, selector = key.partition("/")
        try:
            bench = get_benchmark(bench_name)
        except UnknownInstanceError as exc:
            raise SpecError(f"{where}: {key!r}: {exc}") from None
        except (ImportError, AttributeError) as exc:
            raise SpecError(f"{where}: {key!r}: benchmark {bench_name!r} is not available here ({exc})") from None
        try:
            ids = frozenset(bench.list_instances(selector))
        except DataNotFoundError as exc:
            if bench_name in benchmarks:
                raise SpecError(f"{where}: {key!r}: {exc}") from None
            continue
        except (UnknownInstanceError, EnvError, ValueError) as exc:
            raise SpecError(f"{where}: {key!r}: {exc}") from None
        if not ids:
            raise SpecError(f"{where}: {key!r} matches no {bench_name} instance")
        out.append((key, ids, float(value)))
    return out


def step_multiplier_for(spec: SweepSpec, index: int, instance_id: str, task_multipliers: list[TaskMultiplier]) -> float:
    """The step multiplier of ``spec.methods[index]`` on ``instance_id``: the ``step_multipliers``
    key that covers the instance, else the method's ``step_multiplier``, else the sweep's. Two keys
    that cover one instance with different values are refused (which one wins would be a guess)."""
    m = spec.methods[index]
    hits = [(key, value) for key, ids, value in task_multipliers if instance_id in ids]
    if len({value for _, value in hits}) > 1:
        (k1, v1), (k2, v2) = hits[0], next(h for h in hits if h[1] != hits[0][1])
        raise SpecError(
            f"methods[{index}] ({m.name}): step_multipliers: {k1!r} (x{v1:g}) and {k2!r} (x{v2:g}) both cover "
            f"{instance_id}; give each task one multiplier"
        )
    if hits:
        return hits[0][1]
    return float(m.step_multiplier if m.step_multiplier is not None else spec.step_multiplier)


def with_release_digest(
    spec: SweepSpec, m: Any, instance_id: str, method_config: str, cache: dict[tuple[str, str, str], str]
) -> str:
    """``method_config`` with ``prompts`` pinned to the digest of the released text this instance's
    episode will show (``release:<sha256>``), so the unit's hash covers that text: an edited release
    file makes a different unit. SpecError (naming the fetch command) when the release folder is
    missing or has no prompts for the method here: before anything runs."""
    bench, split, task = place_of(instance_id)
    # the method is part of the key: two methods can share one settings text (ReAct and Act under
    # the same profile) and still read different release files
    key = (m.method, method_config, f"{bench}/{split}/{task}")
    if key not in cache:
        where = f"methods[{spec.methods.index(m)}] ({m.name}): prompts: release"
        values = json.loads(method_config)
        try:
            text = release_text(
                release_folder(),
                m.method,
                bench,
                split,
                task,
                think=values.get("think", "latest"),
                name_only=bool(values.get("name_only", False)),
            )
        except ReleaseMissing as exc:
            raise SpecError(f"{where}: {exc}") from None
        except ReleaseUnavailable as exc:
            raise SpecError(f"{where}: {exc} (use prompts: ours there)") from None
        cache[key] = json.dumps({**values, "prompts": f"release:{text.digest}"}, sort_keys=True)
    return cache[key]


# --------------------------------------------------------------------------------------------
def earlier_id_options(spec: SweepSpec | None) -> Mapping[str, Mapping[str, Any]] | None:
    """The environment options in the id (:func:`workers.envs.options.identity_options`) of each
    instance of ``spec``, a run folder's stored spec; None when it cannot be read here (a benchmark
    or its data is gone). Instances are listed only when some entry has such an option."""
    if spec is None:
        return None
    try:
        per_entry = [identity_options(get_benchmark(e.benchmark).declared_options(), e.options) for e in spec.environments]
        if not any(per_entry):
            return defaultdict(dict)
        # an option it gave that is refused now (FEVER's ineffective ``seed``) chose nothing: left out
        envs = [
            e.model_copy(
                update={"options": {k: v for k, v in e.options.items() if k in get_benchmark(e.benchmark).declared_options()}}
            )
            for e in spec.environments
        ]
        return {
            inst: identity_options(get_benchmark(inst.split("/", 1)[0]).declared_options(), o)
            for inst, o in resolve_instances(envs)
        }
    except (SpecError, UnknownInstanceError, ImportError, AttributeError):
        return None


def keep_earlier_ids(plan: Plan, old: Mapping[str, Any] | None, earlier_spec: SweepSpec | None) -> Plan:
    """``plan`` with the ids of a run written before environment options were in the unit id.

    Such a run's units have their ``plain_id`` (no options hashed), whatever options they ran
    with. A unit whose stored id is its ``plain_id`` and that ran with the options it has now
    (the stored plan's ``env_options``; for a plan.json written before those were kept, the stored
    spec.yaml's, ``earlier_spec``) keeps that id: its finished episodes stay finished. Ran with
    other options, it gets its new id and is ``changed``. One case cannot be told apart by id: a
    unit that ran with options that are now removed (its plain id is its new id too); that is
    refused (SpecError, one line) rather than its episodes taken as done."""
    old_units = {u["key"]: u for u in (old or {}).get("units", []) if isinstance(u, Mapping) and isinstance(u.get("key"), str)}
    if not old_units:
        return plan
    from_spec: Mapping[str, Mapping[str, Any]] | None = None
    spec_read = False

    def ran_with(prev: Mapping[str, Any], instance_id: str) -> Mapping[str, Any] | None:
        nonlocal from_spec, spec_read
        if isinstance(prev.get("env_options"), Mapping):
            return prev["env_options"]
        if not spec_read:
            from_spec, spec_read = earlier_id_options(earlier_spec), True
        return None if from_spec is None else from_spec.get(instance_id, {})

    units: list[Unit] = []
    removed: list[str] = []
    for u in plan.units:
        prev = old_units.get(u.key)
        prev_id = prev.get("unit_id") if prev is not None else None
        if prev is None or not u.plain_id or prev_id != u.plain_id:
            units.append(u)
            continue
        ran = ran_with(prev, u.instance_id)
        if prev_id == u.unit_id:  # no options in its id now
            if ran:
                removed.append(f"{u.key} ({', '.join(f'{k}: {v}' for k, v in sorted(ran.items()))})")
            units.append(u)
        elif ran is not None and dict(ran) == dict(u.id_options):
            units.append(replace(u, unit_id=u.plain_id, earlier_id=True))
        else:
            units.append(u)
    if removed:
        raise SpecError(
            f"{len(removed)} unit(s) of this run ran with environment options it no longer sets (first: {removed[0]}), "
            "and were planned before options were in the unit id: their episodes would be taken as done. "
            "Set the options again, or start a new run (another output:)"
        )
    return Plan(plan.spec, units)


# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PlanDiff:
    """How a new plan compares with the stored one, as lists of unit keys: ``changed`` keys hash differently now
    (their settings changed), ``removed`` keys are in the old plan only."""

    new: list[str]
    unchanged: list[str]
    changed: list[str]
    removed: list[str]

    def describe(self) -> str:
        """The diff in one line for the plan printout, e.g. "3 new, 10 unchanged, 0 changed"."""
        return f"{len(self.new)} new, {len(self.unchanged)} unchanged, {len(self.changed)} changed" + (
            f", {len(self.removed)} no longer in the spec" if self.removed else ""
        )


def diff_plans(old: Mapping[str, Any] | None, plan: Plan) -> PlanDiff:
    """Compare a stored plan.json with a new plan by unit key and hash."""
    old_units = (old or {}).get("units", [])
    old_by_key = {u["key"]: u["unit_id"] for u in old_units}
    new_keys = set()
    new, unchanged, changed = [], [], []
    for u in plan.units:
        new_keys.add(u.key)
        prev = old_by_key.get(u.key)
        if prev is None:
            new.append(u.key)
        elif prev == u.unit_id:
            unchanged.append(u.key)
        else:
            changed.append(u.key)
    removed = [k for k in old_by_key if k not in new_keys]
    return PlanDiff(new, unchanged, changed, removed)


# --------------------------------------------------------------------------------------------
# the order units start in
# --------------------------------------------------------------------------------------------
def order_seed(spec: SweepSpec) -> int:
    """The seed of the interleaved order: the first 8 bytes of sha256("recap-order:" + run
    name). The same run name gives the same order, whatever the output folder or the caps."""
    return int.from_bytes(hashlib.sha256(f"recap-order:{spec.run}".encode()).digest()[:8], "big")


def stratum(instance_id: str) -> str:
    """The group an instance is spread over in the interleaved order: the benchmark and the
    second part of its id (a split, task type or size: ``robotouille/synchronous``,
    ``alfworld/heat``, ``blocksworld/3``)."""
    parts = instance_id.split("/")
    return "/".join([parts[0], parts[1].split("@", 1)[0]]) if len(parts) > 1 else parts[0]


def order_units(units: Sequence[Unit], spec: SweepSpec) -> list[Unit]:
    """The order the driver starts ``units`` in (``spec.order``); unit ids are untouched.

    ``plan``: the units as given (the plan's order: instances, then methods, models, sampling seeds).

    ``interleaved`` (default), so that a cap that binds early leaves a balanced subsample:

    1. one sequence of (instance, sampling seed) pairs, shared by every arm: sampling seeds in spec
       order, the slowest; for each sampling seed every instance once, taking the strata (:func:`stratum`) in turn
       and, within a stratum, its instances in a shuffle seeded by :func:`order_seed`. Any
       prefix thus covers as many instances as it can before it repeats one with another sampling seed,
       spread over benchmarks and splits;
    2. arms (method label x model label, in spec order) take turns: round ``r`` gives each arm
       its next pair of the sequence, starting at arm ``r mod A`` (a cap never favours the same
       arm). After any prefix of ``k`` units the per-arm counts differ by at most 1 (while no arm
       has run out), and in a full plan every arm gets the same pairs first, so the units a
       capped run finished are paired across methods and models.

    Deterministic: the same units and spec give the same order; a resume keeps it (what is
    done is skipped, the rest keeps its relative order).
    """
    if spec.order == "plan":
        return list(units)
    rng = random.Random(order_seed(spec))
    by_stratum: dict[str, list[str]] = defaultdict(list)
    for inst in sorted({u.instance_id for u in units}):
        by_stratum[stratum(inst)].append(inst)
    strata = sorted(by_stratum)
    for s in strata:
        rng.shuffle(by_stratum[s])
    rng.shuffle(strata)
    instances: list[str] = []
    for i in range(max((len(v) for v in by_stratum.values()), default=0)):
        instances += [by_stratum[s][i] for s in strata if i < len(by_stratum[s])]
    seed_rank = {s: i for i, s in enumerate(spec.sampling_seeds)}
    inst_rank = {inst: i for i, inst in enumerate(instances)}
    arm_rank = {(m.name, o.name): i * len(spec.models) + j for i, m in enumerate(spec.methods) for j, o in enumerate(spec.models)}
    arms: dict[tuple[str, str], list[Unit]] = defaultdict(list)
    for u in units:
        arms[(u.method_label, u.model_label)].append(u)
    queues = [
        sorted(arms[a], key=lambda u: (seed_rank.get(u.sampling_seed, len(seed_rank)), u.sampling_seed, inst_rank[u.instance_id]))
        for a in sorted(arms, key=lambda a: (arm_rank.get(a, len(arm_rank)), a))
    ]
    out: list[Unit] = []
    n = len(queues)
    for r in range(max((len(q) for q in queues), default=0)):
        for j in range(n):
            q = queues[(r + j) % n]
            if r < len(q):
                out.append(q[r])
    return out
