"""A snapshot is served only as it was sealed (issue 35 item 10): every served field of a request
row is under its row hash, the rows under the manifest a run writes when it ends, the manifest
under the digest in run.json. Any tampering, an old snapshot without a manifest: refused in one
line, and ``recap run`` on such a snapshot exits 2 before any episode (no folder, no model call)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pipeline.cli import main
from schemas.parts import RUN_FILE
from tests.workers.envs.fever import tampering
from tests.workers.envs.fever.tampering import BASE, BODY_A, BODY_B, A, B
from workers.envs.fever.manifest import MANIFEST_FILE, RUN_KEY
from workers.envs.fever.pages import Snapshot

RERECORD = "re-record it (a run with wikipedia: live seals its pages when it ends)"


def test_a_sealed_snapshot_is_served_as_recorded(tmp_path: Path):
    run = tampering.sealed_run(tmp_path / "run")
    snap = Snapshot(run)
    assert snap.get(A).text() == BODY_A.decode() and snap.get(B).text() == BODY_B.decode() and len(snap) == 2
    manifest = json.loads((run / MANIFEST_FILE).read_text())
    assert json.loads((run / RUN_FILE).read_text())[RUN_KEY] == manifest["digest"]
    assert [e[0] for e in manifest["entries"]] == [A, A, B]  # every request row, duplicates included


@pytest.mark.parametrize(
    ("name", "detail"),
    [
        ("encoding", f"the row of {A!r} was changed"),
        ("body+sha256", f"the row of {A!r} was changed"),
        ("relabel", f"the row of {A!r} was changed"),
        ("swap urls", f"the row of {A!r} was changed"),
        ("deleted row", f"the row for {B!r} is missing (deleted, or relabelled)"),
        ("added row", f"a row for {BASE + 'Gamma'!r} is not in it (added, or relabelled)"),
    ],
)
def test_every_tampering_is_refused_in_one_line(tmp_path: Path, name: str, detail: str):
    run = tampering.sealed_run(tmp_path / "run")
    tampering.TAMPERINGS[name](run)
    assert tampering.load(run) == f"{str(run)!r} does not match its sealed page manifest: {detail}; {RERECORD}"


def test_a_manifest_rewritten_to_match_tampered_rows_is_refused(tmp_path: Path):
    run = tampering.sealed_run(tmp_path / "run")
    tampering.TAMPERINGS["manifest rewritten"](run)
    assert tampering.load(run) == (
        f"{str(run)!r}: {MANIFEST_FILE} is not the manifest its run sealed (digest mismatch); {RERECORD}"
    )


def test_an_old_snapshot_without_a_manifest_is_refused_with_how_to_re_record_it(tmp_path: Path):
    run = tampering.sealed_run(tmp_path / "run", sealed=False)  # as recorded before manifests
    assert tampering.load(run) == (
        f"{str(run)!r} has no sealed page manifest (no {MANIFEST_FILE}: recorded before manifests, "
        f"or by a run that did not end); {RERECORD}"
    )
    tampering.seal_run_folder(run)  # a manifest file, but run.json names no digest
    assert f"(no {RUN_KEY} in run.json: " in (tampering.load(run) or "")


def _sweep(tmp_path: Path, snapshot: Path, claims_dir: Path) -> Path:
    spec = tmp_path / "sweep.yaml"
    spec.write_text(
        f"""run: replay
output: {tmp_path / "out"}
models:
  - model: offline/expert
methods:
  - method: react
environments:
  - benchmark: fever
    tasks: [all]
    options: {{data_dir: "{claims_dir}", wikipedia: "snapshot:{snapshot}"}}
"""
    )
    return spec


@pytest.mark.parametrize("name", sorted(tampering.TAMPERINGS))
def test_recap_run_on_a_tampered_snapshot_exits_2_in_one_line_before_any_episode(tmp_path, capsys, claims_dir, name):
    run = tampering.sealed_run(tmp_path / "snap")
    tampering.TAMPERINGS[name](run)
    code = main(["run", str(_sweep(tmp_path, run, claims_dir)), "--progress", "off"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    head = "recap: error: sweep.yaml: environments[0] (fever): cannot open fever/1001: SnapshotError: "
    full = head + (tampering.load(run) or "")  # the refusal, shortened to the one-line limit in the middle
    assert err[0].startswith(head) and full != head and all(piece in full for piece in err[0].split("..."))
    assert not (tmp_path / "out").exists()  # nothing written, no episode, no model call


def test_run_json_names_the_digest_only_when_a_run_recorded_pages():
    from pipeline.store import RunIdentity

    plain = RunIdentity(run_id="r", run="x", created_at=1.0)
    assert "wiki_manifest_sha256" not in json.loads(plain.to_json())  # what an earlier recap reads
    sealed = RunIdentity(run_id="r", run="x", created_at=1.0, wiki_manifest_sha256="ab" * 32)
    assert RunIdentity(**json.loads(sealed.to_json())) == sealed


def test_a_run_seals_its_pages_when_it_ends_and_a_tampered_copy_is_refused(ray_address, tmp_path, claims_dir, standin, capsys):
    """The driver's part: a live FEVER sweep (in-process executor) ends with the manifest and its
    digest in run.json; the folder serves as a snapshot; one changed encoding and it is refused."""
    from pipeline.driver import Driver, prepare
    from pipeline.gateway_backend import make_backend
    from pipeline.spec import parse_spec

    def sweep(out: Path, wiki: str) -> str:
        options = f'data_dir: "{claims_dir}", wikipedia_url: "{standin.base_url}"{wiki}'
        return (
            f"run: {out.name}\noutput: {out}\nmodels: [{{model: offline/expert}}]\nmethods: [{{method: react}}]\n"
            f"environments: [{{benchmark: fever, tasks: [all], options: {{{options}}}}}]\nworkers: 1\n"
        )

    live = tmp_path / "live"
    text = sweep(live, "")
    spec = parse_spec(text, "sweep.yaml")
    assert Driver(prepare(spec, text), make_backend(spec), progress="off", executor="in-process").run().exit_code() == 0
    manifest = json.loads((live / MANIFEST_FILE).read_text())
    assert json.loads((live / RUN_FILE).read_text())[RUN_KEY] == manifest["digest"]
    # one search per claim and Mercury's disambiguation page's [Mercury]: every request row sealed
    assert len(manifest["entries"]) == len(standin.requests) == 4
    assert len(Snapshot(live)) == 4

    tampering._rewrite(live, "wiki_requests", lambda rows: [{**rows[0], "encoding": "cp1252"}, *rows[1:]])
    replay = tmp_path / "replay.yaml"
    replay.write_text(sweep(tmp_path / "replay", f', wikipedia: "snapshot:{live}"'))
    code = main(["run", str(replay), "--progress", "off"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "does not match its sealed page manifest" in err[0], err
    assert not (tmp_path / "replay").exists() and len(standin.requests) == 4
