"""The report's files, ``recap sql``'s text and the viewer's pages over fixed inputs are byte for byte the golden
files in tests/reports/golden/, written by ``python -m tests.reports.golden`` at commit cd47c8e (before issue 26's
refactor of reports/): a change of structure must not change one byte of what a reader gets."""

from __future__ import annotations

import difflib

from tests.reports.golden import GOLDEN_DIR, golden_outputs


def test_outputs_are_the_golden_files(tmp_path):
    got = golden_outputs(tmp_path)
    want = {str(p.relative_to(GOLDEN_DIR)): p.read_bytes() for p in sorted(GOLDEN_DIR.rglob("*")) if p.is_file()}
    assert sorted(got) == sorted(want)
    changed = [name for name in want if got[name] != want[name]]
    if changed:
        name = changed[0]
        diff = difflib.unified_diff(
            want[name].decode(errors="replace").splitlines(),
            got[name].decode(errors="replace").splitlines(),
            "golden/" + name,
            "now/" + name,
            lineterm="",
            n=1,
        )
        raise AssertionError(f"{len(changed)} file(s) changed: {changed[:10]}\n" + "\n".join(list(diff)[:40])[:4000])
