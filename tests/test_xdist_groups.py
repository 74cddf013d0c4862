"""The suite's shared runs rely on pytest-xdist's ``--dist loadgroup`` (tests/conftest.py puts each
reader of a shared run into that run's group, so the run is made once): check that the installed
pytest / pytest-xdist pair really keeps a group on one worker. Under pytest 9.2 with
pytest-xdist 3.8 it did not (the group never reached the test ids), and every shared run was made
once per worker - slower, and no test failed."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

GROUPED = textwrap.dedent(
    """
    import os
    import pytest

    @pytest.mark.xdist_group("one")
    @pytest.mark.parametrize("i", range(6))
    def test_grouped(i, tmp_path_factory):
        out = os.environ["GROUP_OUT"]
        with open(os.path.join(out, f"{i}"), "w") as fh:
            fh.write(os.environ["PYTEST_XDIST_WORKER"])

    @pytest.mark.parametrize("i", range(6))
    def test_free(i):
        pass
    """
)


def test_a_loadgroup_group_runs_on_one_worker(tmp_path: Path) -> None:
    (tmp_path / "test_grouped.py").write_text(GROUPED)
    out = tmp_path / "out"
    out.mkdir()
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", "2", "--dist", "loadgroup", str(tmp_path)],
        cwd=tmp_path,
        env=dict(os.environ, GROUP_OUT=str(out)),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    workers = {p.name: p.read_text() for p in out.iterdir()}
    assert sorted(workers) == [str(i) for i in range(6)]
    assert len(set(workers.values())) == 1, workers
