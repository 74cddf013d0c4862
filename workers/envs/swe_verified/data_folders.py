"""The SWE-bench Verified data folder as ``recap data`` sees it: loaded, not downloaded file by file.

Its records come from the Hugging Face dataset (through the ``datasets`` library) or a local copy
(``--from FILE``), are checked and stored by :func:`.dataset.load_into`; the folder carries its own
``MANIFEST.sha256`` (the repository cannot pin bytes it has never seen). ``recap data check``
adds the instance count (and whether it is a subset) and how many instances have their image here.
It is asked for by name (``in_all`` False): only swe-verified sweeps need it.
"""

from __future__ import annotations

from pathlib import Path

from workers.envs.data_sources import DataFolder, Group
from workers.sandbox.base import SandboxError

from .dataset import DATASET, INSTANCES_FILE, LOCATION, SOURCE_FILE, SPLIT, load_into, read_folder, read_source
from .images import images_line, local_images


def _no_members(member: str) -> str | None:
    """Nothing is extracted from an archive."""
    return None


def check_notes(folder: Path) -> list[str]:
    """``recap data check``'s extra lines for a verified folder: the instances (subset or not) and
    how many have their image here (one ``docker images`` listing)."""
    source = read_source(folder)
    recs = read_folder(folder)
    kind = "a subset of the 500" if source.subset else "the full test split"
    lines = [f"{len(recs)} instances ({kind}) from {source.source}"]
    try:
        present = local_images()
    except SandboxError as exc:
        return [*lines, f"images: not checked: {exc}"]
    return [*lines, images_line([r["instance_id"] for r in recs], present)]


FOLDER = DataFolder(
    name="swebench-verified",
    title=f"SWE-bench Verified ({DATASET}, {SPLIT})",
    location=LOCATION,
    groups=(Group(INSTANCES_FILE, fetchable=True), Group(SOURCE_FILE, fetchable=True)),
    sources=(),
    member_path=_no_members,
    after_fetch="each instance runs in the SWE-bench harness's image; `recap data check swebench-verified` says which are here",
    in_all=False,
    load=load_into,
    check_notes=check_notes,
)
