"""The labels an episode row is grouped by, derived one way for the writer and the readers.

Why here: the driver writes them into new rows, and the reader of a part written under schema
version 1 (:mod:`schemas.versions`) derives them for old rows; one definition keeps a new run and
an old one grouped alike. Pure functions of strings, no I/O.
"""

from __future__ import annotations

import json
import re
from typing import Final

#: ALFWorld's evaluation set: ALFRED ``valid_unseen`` (``eval_out_of_distribution``, 134 games)
ALFWORLD_SPLIT = "valid_unseen"
#: ALFWorld's task types by the short names instance ids and the paper's tables use
ALFWORLD_TASK_TYPES = ("put", "clean", "heat", "cool", "examine", "puttwo")
#: the method names a schema version 1 row's label can start with (:func:`parse_default_label`,
#: used only to read those rows): the methods of that time, frozen with the version. It is not
#: the list of today's methods (that is ``recap.methods.METHODS``, where each method is
#: registered): a method added later never wrote a version 1 row, so nothing here changes.
VERSION_1_METHODS = ("recap", "react", "act", "cot", "standard", "adapt")
#: the settings profiles a version 1 label can carry, frozen likewise
VERSION_1_PROFILES = ("paper", "released")
#: the end reason of a row whose unit failed on infrastructure (the model service, a worker)
INFRA_ERROR: Final = "infra_error"
#: LLM error kinds (the first word of a row's error) that say the model service failed
INFRA_ERROR_KINDS = ("rate_limit", "timeout", "server_error", "auth", "connection", "not_found", "sandbox")
#: the kind (first word of the error) of an ``env_error`` row whose sandbox service failed (the
#: Docker daemon unreachable, a container that could not start or is gone): infrastructure, run
#: again by the next resume. A sandbox that fails for the instance itself (an image at the wrong
#: commit) or for the agent (a repository it broke) has no kind: an outcome, like any env_error.
SANDBOX_INFRA_KIND = "sandbox"
#: the end reason of an episode stopped because a Wikipedia answer could not be had or read (FEVER)
WIKI_ERROR: Final = "wiki_error"
#: the kind (first word of the error) of a ``wiki_error`` row that is infrastructure: the site
#: refused or timed out after the retries. A snapshot miss, an unreadable answer or a
#: disambiguation loop would fail the same way again, so they are outcomes like ``env_error``; so
#: are an answer past its deadline (``timeout``: a server dripping its answer drips it again), past
#: the size cap (``too_large``) or redirected off the configured site (``redirect``), issue 35.
WIKI_INFRA_KIND = "unavailable"
#: how the driver's row for a unit it gave up on begins
GAVE_UP_PREFIX = "gave up after"
_GAVE_UP_INFRA = re.compile(r"\(infrastructure: (\w+)\)")
#: what the last error of a give-up row written before the marker existed says of a lost worker
_WORKER_DEATHS = ("ActorDiedError", "RayActorError", "ActorUnavailableError", "WorkerCrashedError", "worker lost")


def infra_failure(end_reason: str | None, error: str | None) -> str | None:
    """The infrastructure failure a terminal row records (``server_error``, ``auth``,
    ``not_found``, ``worker_lost``, ``client`` ...), or None when the row is a real outcome.

    * rows of units the driver gave up on (``"gave up after N failed attempts ..."``): infra
      when the attempts were lost to dying workers or a failing model client (the row says
      ``(infrastructure: KIND)``), not when the agent itself crashed;
    * ``infra_error`` rows (schema version 2): the kind is the first word of the error
      (``"auth: ..."``), a ``bad_request`` that is a 404 is ``not_found``, else ``infra``;
    * ``wiki_error`` rows (FEVER): ``wiki_unavailable`` when the error's kind is ``unavailable``
      (Wikipedia refused or timed out after the retries), else an outcome;
    * ``env_error`` rows: ``sandbox`` when the error's kind is ``sandbox`` (the container service
      failed: :class:`workers.sandbox.base.SandboxUnavailable`), else an outcome;
    * ``llm_error`` rows (version 1 wrote infrastructure failures so): the error starts with
      an infrastructure kind, or is a 404 ``bad_request`` (a wrong ``api_base`` path or model
      name); ``context_length`` and other bad requests are outcomes of the agent's requests.
    """
    text = (error or "").strip()
    if text.startswith(GAVE_UP_PREFIX):
        m = _GAVE_UP_INFRA.search(text)
        if m:
            return m.group(1)
        head = text.split("; last:", 1)
        last = head[1].strip() if len(head) > 1 else ""
        if last.startswith("client:"):
            return "client"
        if any(s in last for s in _WORKER_DEATHS):
            return "worker_lost"
        return "infra" if end_reason == INFRA_ERROR else None
    if end_reason == WIKI_ERROR:  # "unavailable: ..." is the site failing, retried like infra_error
        return "wiki_unavailable" if text.split(":", 1)[0].strip() == WIKI_INFRA_KIND else None
    if end_reason == "env_error":  # "sandbox: ..." is the container service failing
        return SANDBOX_INFRA_KIND if text.split(":", 1)[0].strip() == SANDBOX_INFRA_KIND else None
    if end_reason not in ("llm_error", INFRA_ERROR):
        return None
    kind = text.split(":", 1)[0].strip()
    if kind in INFRA_ERROR_KINDS:
        return kind
    if kind == "bad_request" and re.search(r"NotFoundError|\b404\b|[Nn]ot [Ff]ound", text):
        return "not_found"
    return "infra" if end_reason == INFRA_ERROR else None


def place_of(instance_id: str, split: str | None = None, task: str | None = None) -> tuple[str, str, str]:
    """(benchmark, split, task) of an episode row, as rows of schema version 1 are read
    (:mod:`schemas.versions`). New rows are placed by their benchmark's ``place`` hook
    (``workers.envs.registry.place_of``; schemas cannot ask the benchmarks); this rule is frozen
    with version 1 and agrees with the built-ins' hooks (tests/pipeline/test_spec_units.py).

    * ALFWorld: one split, ``valid_unseen``; the task is the task type, the second part of the
      instance id (``alfworld/heat/...`` -> ``heat``), whatever the environment calls it;
    * Robotouille: ``synchronous``/``asynchronous`` and the environment's name, from the id
      (``robotouille/synchronous/6_lettuce_tomato_cheeseburger@42``) when the environment did
      not say (a unit whose worker died before it made one);
    * anything else: what the environment said (empty when it never said).
    """
    parts = instance_id.split("/")
    bench = parts[0]
    if bench == "alfworld" and len(parts) > 1:
        return bench, ALFWORLD_SPLIT, parts[1]
    if bench == "robotouille" and len(parts) > 2:
        return bench, split or parts[1], task or parts[2].split("@", 1)[0]
    return bench, split or "", task or ""


def ablation_of_config(method_config: str | None) -> str | None:
    """The ablation a ReCAP config's settings amount to (the names of ``recap.config.ABLATIONS``:
    ``no_think``, ``think_many``, ``name_only``, ``level_N``, ``no_shortcut``; several joined
    with ``+``), or None for the original settings or a config that is not JSON."""
    try:
        cfg = json.loads(method_config or "")
    except ValueError:
        return None
    if not isinstance(cfg, dict):
        return None
    names = []
    think = cfg.get("think")
    if think == "none":
        names.append("no_think")
    elif think == "many":
        names.append("think_many")
    if cfg.get("name_only") is True:
        names.append("name_only")
    if cfg.get("max_level") is not None:
        names.append(f"level_{cfg['max_level']}")
    if cfg.get("shortcut") is False:
        names.append("no_shortcut")
    return "+".join(names) or None


_DEFAULT_LABEL = re.compile(r"^([a-z_]+)(?:\[([^\]]*)\])?$")


def parse_default_label(label: str) -> tuple[str, str | None, str | None] | None:
    """(method, profile, ablation) of a schema version 1 label in the form a sweep gave an arm
    without a label of its own (``recap``, ``recap[paper]``, ``recap[paper,no_think]``,
    ``recap[level_3]``), or None for any other label (a custom one says nothing reliable)."""
    m = _DEFAULT_LABEL.match(label or "")
    if not m or m.group(1) not in VERSION_1_METHODS:
        return None
    profile = ablation = None
    for part in (m.group(2) or "").split(",") if m.group(2) is not None else []:
        part = part.strip()
        if part in VERSION_1_PROFILES and profile is None and ablation is None:
            profile = part
        elif part and ablation is None:
            ablation = part
        else:
            return None
    return m.group(1), profile, ablation
