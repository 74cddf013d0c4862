"""The Robotouille data folder as ``recap data`` sees it: its file groups, its one download, and
the instances generated after it (see pipeline/data.py for the command and its story).

The upstream repository does not store the 200 benchmark instances nor the two demonstration
instances: the real engine makes them at load time with its seeded generator, so ``fetch``
generates them here (:mod:`workers.envs.robotouille.generator`) from the fetched problem files.
"""

from __future__ import annotations

from pathlib import Path

from workers.envs.data_sources import DataFolder, Group, Source

from . import generator  # called through the module: a test swaps generator.write_instances
from .data import LOCATION

#: upstream repository and the commit the data folder was taken from
REPO_ARCHIVES = "https://github.com/portal-cornell/robotouille/archive"
COMMIT = "c8236a2e3afa75354475ade9147dc38a7e589944"

_INSTANCES_NOTE = (
    "not stored upstream: `recap data fetch robotouille` generates them (recap-eval's "
    "re-implementation of the real engine's seeded generator), or copy them from a complete "
    "Robotouille data folder"
)


def strip_top_folder(member: str) -> str | None:
    """``robotouille-<commit>/domain/x.json`` -> ``domain/x.json`` (GitHub archives' layout)."""
    _top, sep, rest = member.partition("/")
    return rest if sep and rest else None


def generate_instances(folder: Path) -> list[str]:
    """instances/ and instances_train/ from the fetched problem files and domain."""
    return generator.write_instances(folder, folder)


FOLDER = DataFolder(
    name="robotouille",
    title="Robotouille",
    location=LOCATION,
    groups=(
        Group("LICENSE", fetchable=True),
        Group("domain/", fetchable=True),
        Group("environments/", fetchable=True),
        Group("agents/", fetchable=True),
        Group("conf/", fetchable=True),
        Group("instances/", fetchable=True, note=_INSTANCES_NOTE, generated=True),
        Group("instances_train/", fetchable=True, note=_INSTANCES_NOTE, generated=True),
        Group(
            "trajectories/",
            fetchable=False,
            required=False,
            note="recorded on the real engine; only `recap env replay` and the tests read them",
        ),
    ),
    sources=(Source(f"{COMMIT}.tar.gz", f"{REPO_ARCHIVES}/{COMMIT}.tar.gz", "tar.gz"),),
    member_path=strip_top_folder,
    after_fetch=(
        "instances/ and instances_train/ were generated here (recap-eval's re-implementation of the "
        "real engine's seeded generator; they match the pinned digests of generated files)"
    ),
    generate=generate_instances,
)
