"""Write the demo sweep for the data this machine has (used by scripts/demo.sh).

The demo runs Robotouille and ALFWorld. A benchmark whose data cannot be found (see
``recap data list``) is left out of the sweep with a line saying how to fetch it, so a fresh
machine still gets a demo of what it can run; with neither, the built-in blocksworld stands in.

    python scripts/demo_spec.py examples/demo.yaml OUT.yaml   # prints one line per benchmark left out
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import yaml  # noqa: E402

from workers.envs.registry import get_benchmark  # noqa: E402


def available(benchmark: str) -> str | None:
    """None when one instance of ``benchmark`` can be listed and opened, else the reason."""
    try:
        bench = get_benchmark(benchmark)
        ids = bench.list_instances(None)
        bench.make(ids[0]).close()
    except Exception as exc:  # missing folder, missing package, broken data
        return str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return None


def main(src: str, dst: str) -> int:
    """Copy the sweep ``src`` to ``dst`` keeping only the environments this machine has data for
    (the built-in blocksworld when none), printing why each other one is left out; returns the exit
    status (0)."""
    spec = yaml.safe_load(Path(src).read_text())
    kept = []
    for env in spec["environments"]:
        why = available(env["benchmark"])
        if why is None:
            kept.append(env)
        else:
            print(f"demo: {env['benchmark']} left out ({why}); get it with: .venv/bin/recap data fetch {env['benchmark']}")
    if not kept:
        print("demo: no benchmark data found; running the built-in blocksworld instead")
        kept = [{"benchmark": "blocksworld", "tasks": ["3"], "limit": 2}]
    spec["environments"] = kept
    Path(dst).write_text(yaml.safe_dump(spec, sort_keys=False))
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
