"""What a benchmark declares about how the methods run on it, without recap knowing its name.

Why: a method's profile (``paper``, ``released``) can mean different settings on different
benchmarks (the paper runs Robotouille's own ReAct protocol on Robotouille and Yao et al.'s on
ALFWorld; the authors' released prompts exist for two benchmarks only). Those differences are
facts about the benchmark, so the benchmark declares them: each built-in benchmark's folder
holds its protocol (``workers/envs/<name>/protocol.py``) and its
``workers.envs.registry.Benchmark`` (a :class:`BenchmarkProtocol`) hands it to
:func:`recap.config.build_config`. recap never compares a benchmark's name, so a new benchmark
changes no method: it declares nothing (the defaults below) or overrides these hooks.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # annotations only: recap.config imports this module
    from recap.config import AgentConfig


class BenchmarkProtocol:
    """The hooks :func:`recap.config.build_config` asks a benchmark; each default says "nothing
    special here", so a benchmark overrides only what it has to say."""

    name: str = ""

    def profile_settings(
        self, config_cls: type[AgentConfig], profile: str, ablation: str | None, generic: dict[str, Any]
    ) -> dict[str, Any]:
        """What ``profile`` sets for a method (its config class ``config_cls``) on this benchmark,
        given what it sets anywhere (``generic``: the method's own
        :meth:`recap.config.AgentConfig.profile_defaults`). The result replaces ``generic``, so a
        benchmark may add, change or drop settings. Default: ``generic`` unchanged."""
        return generic

    def release_prompt_settings(self, config_cls: type[AgentConfig]) -> dict[str, Any]:
        """Settings the authors' released prompt for a method implies on this benchmark (the reply
        format it asks for); ``prompts: release`` applies them. Default: none (no released
        prompts, or ones that imply nothing)."""
        return {}
