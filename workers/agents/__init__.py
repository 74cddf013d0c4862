"""Agents that run a third-party package's own loop through our model client and environments.

Why here and not in :mod:`recap`: such an agent imports the package (and the package does I/O of
its own at import), which ``recap/`` must stay free of; the method itself is still an
:class:`recap.agent.Agent`, so runs, records, caps and reports treat it like any other.

Importing this package registers its methods by reference (nothing of the third-party package is
imported until an episode plays): :mod:`workers.episode_worker` imports it, so the driver (which
plans units through it) and every episode worker know the names.

* ``mini_swe``: mini-SWE-agent's own ``DefaultAgent`` loop with its SWE-bench configuration
  (:mod:`workers.agents.mini_swe`), the paper's ReAct baseline on SWE-bench as the paper ran it.
"""

from __future__ import annotations

from recap.method_registry import METHODS

#: the methods this package adds, by name: (agent class, config class) references
PACKAGE_METHODS = {"mini_swe": ("workers.agents.mini_swe:MiniSweAgent", "workers.agents.mini_swe:MiniSweConfig")}

for _name, _source in PACKAGE_METHODS.items():
    if _name not in METHODS:
        METHODS.register(_name, _source)
