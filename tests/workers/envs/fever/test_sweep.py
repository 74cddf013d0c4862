"""FEVER through the pipeline: a Ray sweep (recap, react, cot with the offline expert) against the
Wikipedia stand-in writes every page it read into the run folder, and the same sweep replayed from
that run folder with the server stopped sees identical observations after 0 requests; ADaPT on
FEVER is refused before anything is written."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.driver import Driver, prepare
from pipeline.gateway_backend import make_backend
from pipeline.spec import parse_spec
from pipeline.sqlview import open_tables
from pipeline.store import RunStore
from reports.build import ReportOptions, build_report
from reports.views import open_runs
from workers.envs.fever.claims import LABELS, PAPER_INDEX_RANGE, paper_indices
from workers.envs.fever.standin import StandIn

ENTITIES = ("Nikolaj Coster-Waldau", "Mercury", "Xyzzy qwerty")
#: the paper's first three claims of the file the fixture writes (ids 10000 + line number)
CLAIM_IDS = tuple(f"fever/{10_000 + i}" for i in paper_indices()[:3])


@pytest.fixture(scope="module")
def paper_claims(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """A claims file as long as the release's shuffled range, so ``limit: 3`` takes the paper's
    first three; those three cite pages the stand-in serves (an article, a disambiguation page
    whose bracketed search lists results, a missing page), one of each label."""
    folder = tmp_path_factory.mktemp("fever-data")
    first = paper_indices()[:3]
    rows = []
    for i in range(PAPER_INDEX_RANGE):
        row = {"id": 10_000 + i, "verifiable": "VERIFIABLE", "label": LABELS[i % 3], "claim": f"Filler claim {i}."}
        if i in first:
            k = first.index(i)
            page = ENTITIES[k].replace(" ", "_")
            row.update(label=LABELS[k], claim=f"{ENTITIES[k]} is the subject of claim {k}.")
            row["evidence"] = [[[1, 2, page, 0]]] if k < 2 else [[[1, None, None, None]]]
        rows.append(json.dumps(row))
    (folder / "paper_dev.jsonl").write_text("\n".join(rows) + "\n", encoding="utf-8")
    # the planner lists it and Ray's workers find it through FEVER_DATA, which the local cluster
    # forwards when it starts: so this fixture comes before ray_address in the tests' arguments
    before = os.environ.get("FEVER_DATA")
    os.environ["FEVER_DATA"] = str(folder)
    yield folder
    if before is None:
        os.environ.pop("FEVER_DATA", None)
    else:
        os.environ["FEVER_DATA"] = before


def sweep(out: Path, wiki: str) -> str:
    return f"""run: {out.name}
output: {out}
models:
  - model: offline/expert
methods:
  - method: recap
  - method: react
  - method: cot
environments:
  - benchmark: fever
    tasks: [paper]
    limit: 3
    options: {{{wiki}}}
workers: 2
"""


def run_sweep(out: Path, text: str) -> None:
    spec = parse_spec(text, "sweep.yaml")
    summary = Driver(prepare(spec, text), make_backend(spec), progress="off").run()
    assert (summary.total, summary.finished_now, summary.exit_code()) == (9, 9, 0)


def observations(out: Path) -> list[tuple]:
    con, bad = open_tables(RunStore(out))
    assert bad == []
    return con.execute(
        """select e.method, e.instance_id, s."index", s.action, s.observation, s.done, s.success
           from steps s join episodes e using (episode_id) order by 1, 2, 3"""
    ).fetchall()


def user_messages(out: Path) -> list[tuple]:
    con, _ = open_tables(RunStore(out))
    return con.execute(
        """select e.method, e.instance_id, m.seq, m.kind, m.content
           from messages m join episodes e using (episode_id) order by 1, 2, 3"""
    ).fetchall()


@pytest.mark.slow  # two Ray sweeps of 9 episodes (~75 s on 2 shared cores)
def test_live_sweep_records_pages_and_snapshot_replays_them(paper_claims, ray_address, tmp_path):
    server = StandIn().start()
    base = server.base_url
    live = tmp_path / "live"
    try:
        run_sweep(live, sweep(live, f"wikipedia_url: {base}"))
    finally:
        server.stop()
    # recap and react search each claim's entity once (the disambiguation page: its bracketed
    # retry too), then give the label; cot gives the verdict alone and never searches
    searches = ["Nikolaj+Coster-Waldau", "Mercury", "%5BMercury%5D", "Xyzzy"]
    assert sorted(server.requests) == sorted(f"/w/index.php?search={s}" for s in searches * 2)
    steps = observations(live)
    assert [(r[0], r[1], r[3]) for r in steps] == [
        ("cot", CLAIM_IDS[2], "finish[NOT ENOUGH INFO]"),
        ("cot", CLAIM_IDS[0], "finish[SUPPORTS]"),
        ("cot", CLAIM_IDS[1], "finish[REFUTES]"),
        *[
            (method, instance, action)
            for method in ("react", "recap")
            for instance, action in (
                (CLAIM_IDS[2], "search[Xyzzy]"),
                (CLAIM_IDS[2], "finish[NOT ENOUGH INFO]"),
                (CLAIM_IDS[0], "search[Nikolaj Coster-Waldau]"),
                (CLAIM_IDS[0], "finish[SUPPORTS]"),
                (CLAIM_IDS[1], "search[Mercury]"),
                (CLAIM_IDS[1], "finish[REFUTES]"),
            )
        ],
    ]
    by_action = {(r[0], r[3]): r[4] for r in steps}
    assert (
        by_action[("react", "search[Mercury]")] == "Could not find [Mercury]. Similar: ['Mercury (planet)', 'Mercury (element)']."
    )
    assert by_action[("recap", "finish[SUPPORTS]")] == "Episode finished, reward = 1\n"

    con, bad = open_tables(RunStore(live))
    assert bad == []
    assert con.execute("select method, end_reason, count(*) from episodes group by 1, 2 order by 1, 2").fetchall() == [
        ("cot", "success", 3),
        ("react", "success", 3),
        ("recap", "success", 3),
    ]
    # content-addressed: the bodies by sha256 (each of the 2 worker processes writes a body it
    # read at most once), every request pointing at one, its URL as it was sent
    assert con.execute("select count(distinct sha256) from wiki_pages").fetchall() == [(4,)]
    assert con.execute("select count(*) between 4 and 8, count(distinct body) from wiki_pages").fetchall() == [(True, 4)]
    assert sorted(con.execute("select url, count(*) from wiki_requests group by 1").fetchall()) == sorted(
        (f"{base}/w/index.php?search={s}", 2) for s in searches
    )
    assert con.execute(
        "select count(*) from wiki_requests r left join (select distinct sha256 from wiki_pages) p using (sha256) where p.sha256 is null"
    ).fetchall() == [(0,)]
    assert con.execute(
        "select count(*) from wiki_requests r join episodes e using (episode_id) where e.method = 'cot'"
    ).fetchall() == [(0,)]

    check_report(live)

    # the session sealed what it recorded: the manifest's digest in run.json (a snapshot must match it)
    sealed = json.loads((live / "run.json").read_text())["wiki_manifest_sha256"]
    assert sealed == json.loads((live / "wiki_manifest.json").read_text())["digest"]

    replay = tmp_path / "replay"
    run_sweep(replay, sweep(replay, f'wikipedia_url: {base}, wikipedia: "snapshot:{live}"'))
    assert len(server.requests) == 8  # the stopped server got nothing more (a request would fail the episodes)
    assert observations(replay) == steps
    assert user_messages(replay) == user_messages(live)
    con, _ = open_tables(RunStore(replay))
    assert con.execute("select end_reason, count(*) from episodes group by 1").fetchall() == [("success", 9)]
    assert con.execute("select (select count(*) from wiki_requests), (select count(*) from wiki_pages)").fetchall() == [(0, 0)]


def test_adapt_on_fever_is_refused_before_anything_is_written(tmp_path, capsys, paper_claims):
    out = tmp_path / "out"
    spec = tmp_path / "sweep.yaml"
    spec.write_text(sweep(out, "wikipedia_url: http://127.0.0.1:9").replace("method: cot", "method: adapt"))
    code = main(["run", str(spec), "--progress", "off"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err == [
        "recap: error: sweep.yaml: methods[2] (adapt) cannot run on fever: the paper reports no ADaPT result on FEVER "
        "(Table 1: --) and the release has no FEVER ADaPT"
    ]
    assert not out.exists()


def check_report(run: Path) -> None:
    """FEVER's row in the paper's main table (the paper's number withheld: a test double) and the
    per-label table, each claim's label being its episode's task; wiki_pages one row per body."""
    report = build_report([run], ReportOptions(formats=("md",), paper_only=True))
    tables = {t.name: t for t in report.sections[0].tables}
    main_row = tables["paper_main"].rows
    assert [(r["benchmark"], r["model"]) for r in main_row] == [("FEVER", "offline/expert (test double)")]
    for arm in ("recap", "react", "cot"):
        assert main_row[0][arm][:2] == (3, 3) and main_row[0][f"{arm}:paper"] == "[1]"
    labels = tables["paper_fever_labels_offline_expert_test_double"]
    assert [r["label"] for r in labels.rows] == ["SUPPORTS", "REFUTES", "NOT ENOUGH INFO", "All claims"]
    assert [r["recap"][:2] for r in labels.rows] == [(1, 1), (1, 1), (1, 1), (3, 3)]
    assert [r.get("recap:paper") for r in labels.rows] == [None, None, None, "[1]"]
    con = open_runs(run)
    assert con.execute("select count(*), count(distinct sha256) from wiki_pages").fetchall() == [(4, 4)]
