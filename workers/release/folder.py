"""The ``recap-release`` data folder: the authors' prompt and demonstration files at the pinned commit.

Not a benchmark's folder (no benchmark reads it): it is registered beside the benchmarks'
folders (:func:`workers.envs.registry.register_data_folder`) so that ``recap data list/check/fetch
recap-release`` treat it like theirs, and it is left out of ``all`` (only ``prompts: release``
runs need it). Its one source is the repository itself at :data:`COMMIT`: ``fetch`` takes only
the files the manifest lists (``git archive`` of those paths), from GitHub or from ``--mirror``,
a local clone or a git URL.
"""

from __future__ import annotations

from workers.envs.data_paths import DataLocation
from workers.envs.data_sources import DataFolder, Group, Source

NAME = "recap-release"
#: the authors' repository and the commit the paper's code was released at
REPO_URL = "https://github.com/ReCAP-Stanford/ReCAP.git"
COMMIT = "2fb112ffad685c7c6f7de86d5487ecca6f566fcc"
ENV_VAR = "RECAP_RELEASE_DATA"
#: how a run or a message tells the user to get the folder
FETCH_COMMAND = f"recap data fetch {NAME}"

LOCATION = DataLocation(
    name=NAME,
    title="ReCAP release (prompts and demonstrations)",
    env_var=ENV_VAR,
    marker="robotouille-baselines/agents/prompt_builder/prompts",
)


def keep_path(member: str) -> str | None:
    """``git archive`` members are already paths in the repository: kept as they are."""
    return member or None


FOLDER = DataFolder(
    name=NAME,
    title=LOCATION.title,
    location=LOCATION,
    groups=(
        Group("LICENSE", fetchable=True),
        Group("alfworld-recap/", fetchable=True),
        Group("robotouille-recap/", fetchable=True),
        Group("robotouille-baselines/", fetchable=True),
        Group("fever-recap/", fetchable=True),
    ),
    sources=(Source("ReCAP", REPO_URL, "git", ref=COMMIT),),
    member_path=keep_path,
    after_fetch="`prompts: release` in a sweep's method entry now reads these files",
    in_all=False,
)
