"""The FEVER data folder as ``recap data`` sees it: one claims file, its digest and where it is published.

``paper_dev.jsonl`` is the FEVER 1.0 shared-task development set, the file the authors' FEVER runs
read (``fever-recap/data/paper_dev.jsonl`` of their release); the FEVER project publishes the same
bytes with its dataset release, and the authors' repository holds them too (a second source for
``--mirror``-less fetches is not needed: the digest decides, whatever the source).
"""

from __future__ import annotations

from workers.envs.data_sources import DataFolder, Group, Source

from .claims import CLAIMS_FILE, LOCATION

#: sha256 of paper_dev.jsonl (9,999 claims, 2,168,767 bytes), as ../shared/data/fever/README.md records it
CLAIMS_SHA256 = "41158707810008747946bf23471e82df53e77a513524b9e3ec1c2e674ef5ef8c"
CLAIMS_BYTES = 2_168_767
#: the FEVER dataset's public release of the file
CLAIMS_URL = "https://fever.ai/download/fever/paper_dev.jsonl"
#: the same file in the authors' released repository, at the commit the data README names
RELEASE_COMMIT = "2fb112ffad685c7c6f7de86d5487ecca6f566fcc"
RELEASE_CLAIMS_URL = f"https://raw.githubusercontent.com/ReCAP-Stanford/ReCAP/{RELEASE_COMMIT}/fever-recap/data/{CLAIMS_FILE}"


def _no_members(member: str) -> str | None:
    """A single downloaded file has no archive members."""
    return None


FOLDER = DataFolder(
    name="fever",
    title="FEVER (paper_dev claims)",
    location=LOCATION,
    groups=(Group(CLAIMS_FILE, fetchable=True),),
    sources=(Source(CLAIMS_FILE, CLAIMS_URL, "file", CLAIMS_FILE),),
    member_path=_no_members,
    after_fetch="the claims only: observations come from Wikipedia itself (option wikipedia_url) or a snapshot",
)
