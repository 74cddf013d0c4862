"""Starting (or joining) Ray for a sweep.

Why a module: every process of a run — the driver, the gateway, the episode workers, the sink —
must import litellm offline (``LITELLM_LOCAL_MODEL_COST_MAP``), find this project and the
benchmark data folders. Locally the project may not be pip-installed (a checkout), so its root
is put on the workers' ``PYTHONPATH``; on a cluster the nodes have it installed (cluster.yaml).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from pipeline.spec import RaySpec

PROJECT_ROOT = Path(__file__).resolve().parents[1]
#: forwarded from the driver's environment to every Ray worker when set
FORWARDED_VARS = ("ROBOTOUILLE_DATA", "ALFWORLD_DATA", "RECAP_EVAL_DATA")


def runtime_env() -> dict[str, Any]:
    env_vars = {"LITELLM_LOCAL_MODEL_COST_MAP": "True", "RAY_USAGE_STATS_ENABLED": "0"}
    for name in FORWARDED_VARS:
        if os.environ.get(name):
            env_vars[name] = os.environ[name]
    path = [str(PROJECT_ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    env_vars["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(path))
    return {"env_vars": env_vars}


def init_ray(ray_spec: RaySpec, address: str | None = None) -> bool:
    """Start a local Ray (or join ``address``). Returns True when this call started Ray (and so
    must shut it down); an already initialised Ray (tests share one) is reused as is."""
    import ray

    os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    if ray.is_initialized():
        return False
    address = address or ray_spec.address
    common: dict[str, Any] = {"runtime_env": runtime_env(), "log_to_driver": False,
                              "configure_logging": True, "logging_level": "error"}
    if address:
        ray.init(address=address, **common)
    else:
        ray.init(
            num_cpus=ray_spec.num_cpus or os.cpu_count() or 2,
            include_dashboard=ray_spec.dashboard,
            dashboard_host="127.0.0.1",
            object_store_memory=ray_spec.object_store_mb * 1024 * 1024,
            **common,
        )
    return True
