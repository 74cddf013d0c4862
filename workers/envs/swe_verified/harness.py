"""The SWE-bench harness's per-repository test command, read from the ``swebench`` package.

The harness runs ``MAP_REPO_VERSION_TO_SPECS[repo][version]["test_cmd"]`` (swebench 4.x,
``swebench/harness/constants``; e.g. django 3.0: ``./tests/runtests.py --verbosity 2
--settings=test_sqlite --parallel 1``) in the instance's image. That table is the harness's, kept
up to date by its authors, so it is read from the package (``pip install 'recap-eval[swe]'``)
rather than copied here; without the package a swe-verified episode is refused with one line.
"""

from __future__ import annotations

from typing import Any


class HarnessMissingError(RuntimeError):
    """The ``swebench`` package (4.x) is not importable, or does not know an instance's repo/version."""


def _specs() -> dict[str, dict[str, dict[str, Any]]]:
    try:
        from swebench.harness.constants import MAP_REPO_VERSION_TO_SPECS
    except ImportError:
        raise HarnessMissingError(
            "swe-verified reads each repository's test command from the SWE-bench harness: "
            "pip install 'recap-eval[swe]' (swebench 4.x)"
        ) from None
    specs: dict[str, dict[str, dict[str, Any]]] = MAP_REPO_VERSION_TO_SPECS
    return specs


def test_cmd(repo: str, version: str) -> str:
    """The harness's test command for ``repo`` at ``version``; HarnessMissingError (one line) otherwise."""
    spec = _specs().get(repo, {}).get(version)
    if spec is None or not spec.get("test_cmd"):
        raise HarnessMissingError(f"the SWE-bench harness has no test command for {repo} version {version}")
    cmd = spec["test_cmd"]
    return cmd if isinstance(cmd, str) else " && ".join(cmd)
