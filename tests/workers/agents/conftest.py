"""The fixture repositories and local-sandbox environments of the SWE-bench tests, shared here."""

from tests.workers.envs.swe.conftest import fixtures, sandboxes, swe_env

__all__ = ["fixtures", "sandboxes", "swe_env"]
