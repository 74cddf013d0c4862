"""Preflight of the served models: refused in one line before anything is started.

Two moments:

* :func:`check_serving` with the other preflight checks (``recap run`` / ``resume``, before any
  write): Ray Serve installed, the engine installed (``vllm``, ``sglang``: ``ray.serve.llm`` and
  the engine; ``llama.cpp``: llama-cpp-python with its server), the weights present on this
  machine (a local path, or a hub id in the Hugging Face cache: nothing is downloaded here), the
  engine arguments of the test double known, an hourly price that fits the replicas, and a price
  for a served model under a cap;
* :func:`check_cluster` once Ray is up, before any actor starts: the cluster has the GPUs and
  CPUs that every replica asks for, besides the episode workers' CPUs.
"""

from __future__ import annotations

import importlib.util
import os
from collections.abc import Mapping
from pathlib import Path

from pipeline.errors import PreflightError
from pipeline.serving.engines import serve_plan
from pipeline.spec import SweepSpec

#: what installs each engine (named in the refusal)
INSTALL_HINT = {
    "vllm": "pip install 'ray[llm]' vllm",
    "sglang": "pip install 'ray[llm]' 'sglang[all]'",
    "llama.cpp": "pip install 'llama-cpp-python[server]'",
}
#: the modules each engine needs
ENGINE_MODULES = {
    "vllm": ("vllm", "ray.serve.llm"),
    "sglang": ("sglang", "ray.serve.llm"),
    "llama.cpp": ("llama_cpp", "sse_starlette"),
    "test-double": (),
}
#: the first bytes of every GGUF file (llama.cpp's weights)
GGUF_MAGIC = b"GGUF"
#: the longest a test double's latency may be (seconds)
LATENCY_MAX_S = 60.0


def installed(module: str) -> bool:
    """Whether ``module`` can be imported here (found without importing it)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def hub_cache() -> Path:
    """The Hugging Face hub cache (``HF_HUB_CACHE``, ``HF_HOME/hub``, ``~/.cache/huggingface/hub``)."""
    if os.environ.get("HF_HUB_CACHE"):
        return Path(os.environ["HF_HUB_CACHE"])
    home = os.environ.get("HF_HOME") or os.path.join(os.path.expanduser("~"), ".cache", "huggingface")
    return Path(home) / "hub"


def weights_present(weights: str) -> bool:
    """A local file or folder, or a hub id with a snapshot in the Hugging Face cache."""
    path = Path(os.path.expanduser(weights))
    if path.is_absolute() or weights.startswith((".", "~")):
        return path.exists()
    if path.exists():
        return True
    snapshots = hub_cache() / f"models--{weights.replace('/', '--')}" / "snapshots"
    return snapshots.is_dir() and any(snapshots.iterdir())


def check_gguf(where: str, weights: str | None) -> None:
    """llama.cpp's weights: one GGUF file on this machine (``serve_plan`` made the path absolute:
    the replica runs in another folder). Its first bytes are GGUF's magic, so that a folder, a
    hub id or a file of another format is refused here, not by the server once the replicas start."""
    if weights is None:
        raise PreflightError(f"{where}: serve.weights: llama.cpp needs the path of a GGUF file (*.gguf)")
    path = Path(weights)
    if not weights.endswith(".gguf"):
        raise PreflightError(f"{where}: serve.weights: llama.cpp serves a GGUF file (*.gguf), got {weights}")
    if not path.is_file():
        raise PreflightError(f"{where}: serve.weights {weights} is not a file here (llama.cpp serves a local GGUF file)")
    try:
        with open(path, "rb") as f:
            magic = f.read(len(GGUF_MAGIC))
    except OSError as exc:
        raise PreflightError(f"{where}: serve.weights {weights} cannot be read ({exc.strerror})") from None
    if magic != GGUF_MAGIC:
        raise PreflightError(f"{where}: serve.weights {weights} is not a GGUF file (it does not begin with GGUF)")


def check_serving(spec: SweepSpec) -> None:
    """The served models can start here (see the module docstring); PreflightError otherwise."""
    served = [(i, m) for i, m in enumerate(spec.models) if m.serve is not None]
    if not served:
        return
    if not installed("ray.serve") or not installed("fastapi"):
        i, m = served[0]
        raise PreflightError(f"models[{i}] ({m.name}): serve: Ray Serve is not installed (pip install 'recap-eval[serve]')")
    for i, m in served:
        where = f"models[{i}] ({m.name})"
        plan = serve_plan(m)
        missing = [mod for mod in ENGINE_MODULES[plan.engine] if not installed(mod)]
        if missing:
            raise PreflightError(
                f"{where}: serve.engine {plan.engine} is not installed here (no module {missing[0]}; {INSTALL_HINT[plan.engine]})"
            )
        if plan.engine == "test-double":
            from workers.serving.test_double import ENGINE_ARGS as TEST_DOUBLE_ARGS  # lazy: only a sweep serving one

            unknown = sorted(set(plan.engine_args) - set(TEST_DOUBLE_ARGS))
            if unknown:
                raise PreflightError(
                    f"{where}: serve.engine_args: the test double takes only {' and '.join(TEST_DOUBLE_ARGS)}, not {unknown[0]}"
                )
            running = plan.engine_args.get("max_running", 0)
            if isinstance(running, bool) or not isinstance(running, int) or running < 0:
                raise PreflightError(
                    f"{where}: serve.engine_args.max_running must be a whole number >= 0 (0: no limit), got {running!r}"
                )
            latency = plan.engine_args.get("latency_s", 0.0)
            if isinstance(latency, bool) or not isinstance(latency, (int, float)) or not 0 <= latency <= LATENCY_MAX_S:
                raise PreflightError(
                    f"{where}: serve.engine_args.latency_s must be seconds in [0, {LATENCY_MAX_S:g}], got {latency!r}"
                )
            if plan.weights is not None:
                raise PreflightError(f"{where}: serve.weights: the test double serves no weights; leave it out")
        elif plan.engine == "llama.cpp":
            check_gguf(where, plan.weights)
        elif plan.weights is not None and not weights_present(plan.weights):
            raise PreflightError(
                f"{where}: serve.weights {plan.weights} is neither a local path nor in the Hugging Face cache "
                f"({hub_cache()}); fetch it first (huggingface-cli download {plan.weights})"
            )
        if plan.engine in ("vllm", "sglang") and plan.gpus < 1:
            raise PreflightError(f"{where}: serve.gpus_per_replica: {plan.engine} needs at least 1 GPU per replica")
        if m.prices is not None and m.prices.gpu_hour is not None and plan.gpus == 0:
            raise PreflightError(f"{where}: prices.gpu_hour on replicas without GPUs; price them by replica_hour")
        if m.prices is None and (spec.run_cap_usd is not None or m.cap_usd is not None):
            which = "run cap" if m.cap_usd is None else "model cap"
            raise PreflightError(f"{where} has a {which} but no price: give prices: {{gpu_hour: X}} or {{replica_hour: X}}")


def check_cluster(spec: SweepSpec, resources: Mapping[str, float], workers: int) -> None:
    """The cluster's resources (``ray.cluster_resources()``) hold every replica and ``workers``
    episode workers; PreflightError otherwise (nothing was started)."""
    plans = [(i, m, serve_plan(m)) for i, m in enumerate(spec.models) if m.serve is not None]
    if not plans:
        return
    have_gpus = float(resources.get("GPU", 0.0))
    have_cpus = float(resources.get("CPU", 0.0))
    need_gpus = need_cpus = 0.0
    for i, m, plan in plans:
        need_gpus += plan.replicas * plan.gpus
        need_cpus += plan.replicas * plan.cpus
        if need_gpus > have_gpus:
            raise PreflightError(
                f"models[{i}] ({m.name}): serve needs {need_gpus:g} GPUs in all ({plan.replicas} replicas x {plan.gpus}"
                + (" with the models before it" if need_gpus > plan.replicas * plan.gpus else "")
                + f") but the Ray cluster has {have_gpus:g}; nothing was started"
            )
    workers_cpus = workers * spec.ray.worker_cpus
    if need_cpus + workers_cpus > have_cpus + 1e-9:
        raise PreflightError(
            f"serve: the replicas need {need_cpus:g} CPUs and the {workers} episode workers {workers_cpus:g}, "
            f"but the Ray cluster has {have_cpus:g}; nothing was started"
        )
