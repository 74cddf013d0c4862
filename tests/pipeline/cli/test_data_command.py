"""``recap data list/check/fetch`` and the one data-folder rule (workers/envs/data_paths.py).

Nothing here touches the network: ``fetch`` runs against mirrors the tests build in tmp_path
from ../shared/data (a folder, a file:// URL, and an http server on the loopback), and HOME,
RECAP_EVAL_CACHE and the checkout-relative root are pointed into tmp_path.
"""

from __future__ import annotations

import functools
import http.server
import io
import json
import re
import shutil
import sys
import tarfile
import threading
import zipfile
from pathlib import Path

import pytest

from pipeline import data as datacmd
from pipeline.cli.data import data_main
from recap.env import DataNotFoundError
from workers.envs import data_paths
from workers.envs.alfworld import data_folders as alf_folders
from workers.envs.alfworld import games as alf_games
from workers.envs.fever import claims as fever_claims
from workers.envs.robotouille import data as rob_data
from workers.envs.robotouille.data_folders import COMMIT as ROBOTOUILLE_COMMIT
from workers.envs.robotouille.data_folders import FOLDER as ROB_FOLDER

REPO = Path(__file__).resolve().parents[3]
SHARED = REPO.parent / "shared" / "data"
ROB, ALF, ALF212 = SHARED / "robotouille", SHARED / "alfworld", SHARED / "alfworld-2.1.2"
FEVER = SHARED / "fever"


def needs_data(test):
    """The benchmark data is part of the test environment: a missing folder fails the test (with
    where it was looked for), it never skips it."""

    @functools.wraps(test)
    def checked(*args, **kwargs):
        assert ROB.is_dir() and ALF.is_dir() and ALF212.is_dir() and FEVER.is_dir(), (
            f"the tests need the benchmark data in {SHARED}"
        )
        return test(*args, **kwargs)

    return checked


def run(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    code = data_main(list(argv), out, err)
    return code, out.getvalue(), err.getvalue()


@pytest.fixture
def isolated(tmp_path, monkeypatch):
    """No data anywhere: empty HOME, no variables, an empty checkout-relative root."""
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    for var in ("RECAP_EVAL_CACHE", "ROBOTOUILLE_DATA", "ALFWORLD_DATA", "ALFWORLD_DATA_2_1_2", "FEVER_DATA"):
        monkeypatch.delenv(var, raising=False)
    checkout = tmp_path / "shared" / "data"
    monkeypatch.setattr(data_paths, "CHECKOUT_DATA_ROOT", checkout)
    return {
        "home": home,
        "checkout": checkout,
        "cache": home / ".cache" / "recap-eval" / "data",
        "alfworld_cache": home / ".cache" / "alfworld",
    }


def _robotouille_folder(path: Path) -> Path:
    """A real folder that passes the Robotouille layout test (its domain file is a link)."""
    (path / "domain").mkdir(parents=True)
    (path / "domain" / "robotouille.json").symlink_to(ROB / "domain" / "robotouille.json")
    return path


def _alfworld_folder(path: Path, source: Path = ALF) -> Path:
    path.mkdir(parents=True)
    (path / "json_2.1.1").symlink_to(source / "json_2.1.1")
    return path


# ---------------------------------------------------------------------------------------------
# the resolver


@needs_data
def test_resolver_order_robotouille(isolated, tmp_path, monkeypatch):
    checkout = _robotouille_folder(isolated["checkout"] / "robotouille")
    assert rob_data.resolve_data_dir() == checkout.resolve()
    cache = _robotouille_folder(isolated["cache"] / "robotouille")
    assert rob_data.resolve_data_dir() == cache.resolve()
    env = _robotouille_folder(tmp_path / "env")
    monkeypatch.setenv("ROBOTOUILLE_DATA", str(env))
    assert rob_data.resolve_data_dir() == env.resolve()
    option = _robotouille_folder(tmp_path / "option")
    assert rob_data.resolve_data_dir(option) == option.resolve()
    # RECAP_EVAL_CACHE moves recap-eval's cache
    monkeypatch.delenv("ROBOTOUILLE_DATA")
    moved = _robotouille_folder(tmp_path / "moved" / "data" / "robotouille")
    monkeypatch.setenv("RECAP_EVAL_CACHE", str(tmp_path / "moved"))
    assert rob_data.resolve_data_dir() == moved.resolve()


@needs_data
def test_resolver_order_alfworld(isolated, tmp_path, monkeypatch):
    checkout = _alfworld_folder(isolated["checkout"] / "alfworld")
    assert alf_games.resolve_data_dir() == checkout.resolve()
    cache = _alfworld_folder(isolated["cache"] / "alfworld")
    assert alf_games.resolve_data_dir() == cache.resolve()
    upstream = _alfworld_folder(isolated["alfworld_cache"])
    assert alf_games.resolve_data_dir() == upstream.resolve()
    env = _alfworld_folder(tmp_path / "env")
    monkeypatch.setenv("ALFWORLD_DATA", str(env))
    assert alf_games.resolve_data_dir() == env.resolve()
    option = _alfworld_folder(tmp_path / "option")
    assert alf_games.resolve_data_dir(option) == option.resolve()


@needs_data
def test_upstream_cache_with_2_1_2_games_is_skipped(isolated):
    """What alfworld 0.4.2's alfworld-download writes to ~/.cache/alfworld holds 2.1.2 game
    files: the resolver does not take it for the 2.1.1 folder, and list says why."""
    _alfworld_folder(isolated["alfworld_cache"], source=ALF212)
    checkout = _alfworld_folder(isolated["checkout"] / "alfworld")
    assert alf_games.resolve_data_dir() == checkout.resolve()
    code, out, _ = run("list", "alfworld")
    assert code == 0
    assert f"{isolated['alfworld_cache']}: skipped: holds game-file version 2.1.2" in out
    assert re.search(rf"5\. checkout +{re.escape(str(checkout))}: found  <- used", out)


def test_explicit_folder_never_falls_through(isolated, tmp_path, monkeypatch):
    _robotouille_folder(isolated["checkout"] / "robotouille")
    monkeypatch.setenv("ROBOTOUILLE_DATA", str(tmp_path / "nowhere"))
    with pytest.raises(DataNotFoundError, match=r"\(from ROBOTOUILLE_DATA\) does not exist"):
        rob_data.resolve_data_dir()
    with pytest.raises(DataNotFoundError, match="is not a Robotouille data folder"):
        rob_data.resolve_data_dir(tmp_path)
    _alfworld_folder(isolated["checkout"] / "alfworld")
    monkeypatch.setenv("ALFWORLD_DATA", str(tmp_path))
    with pytest.raises(DataNotFoundError) as err:
        alf_games.resolve_data_dir()
    assert str(err.value) == (
        f"ALFWorld data folder {tmp_path.resolve()} (from ALFWORLD_DATA) has no json_2.1.1/valid_unseen; "
        "point ALFWORLD_DATA at the folder that holds it"
    )


def test_nothing_found_says_where_it_looked_and_how_to_fetch(isolated):
    with pytest.raises(DataNotFoundError) as err:
        rob_data.resolve_data_dir()
    message = str(err.value)
    assert message.startswith("no Robotouille data folder: pass data_dir=... or set ROBOTOUILLE_DATA")
    assert "`recap data fetch robotouille`" in message and "\n" not in message
    assert f"{isolated['cache'] / 'robotouille'}: absent" in message
    assert f"{isolated['checkout'] / 'robotouille'}: absent" in message
    with pytest.raises(DataNotFoundError) as err:
        alf_games.resolve_data_dir()
    assert str(err.value).startswith(
        "ALFWorld data folder not set: set ALFWORLD_DATA (or pass data_dir=) to the folder that "
        "holds json_2.1.1/valid_unseen, or run `recap data fetch alfworld` (looked in "
        f"{isolated['alfworld_cache']}: absent;"
    )
    assert list(isolated["home"].iterdir()) == []  # resolving never creates a folder


def test_list_without_any_data(isolated):
    code, out, err = run("list")
    assert code == 1
    assert "robotouille: not found" in out and "alfworld: not found" in out and "fever: not found" in out
    assert "  3. upstream cache     none (Robotouille keeps its data inside its repository checkout)" in out
    lines = err.splitlines()
    assert len(lines) == 4 and all(line.startswith("recap: error: data list: ") for line in lines)
    assert "run `recap data fetch robotouille`" in lines[0]
    assert (
        lines[3] == "recap: error: data list: fever: no folder found; run `recap data fetch fever` (see `recap data list fever`)"
    )


@needs_data
def test_check_the_shared_data(monkeypatch):
    monkeypatch.setenv("ROBOTOUILLE_DATA", str(ROB))
    monkeypatch.setenv("ALFWORLD_DATA", str(ALF))
    monkeypatch.delenv("ALFWORLD_DATA_2_1_2", raising=False)
    monkeypatch.setenv("FEVER_DATA", str(FEVER))
    code, out, err = run("check")
    assert (code, err) == (0, "")
    assert out.splitlines() == [
        f"robotouille: {ROB.resolve()} ($ROBOTOUILLE_DATA): 300 files checked: OK",
        f"alfworld: {ALF.resolve()} ($ALFWORLD_DATA): 404 files checked: OK",
        f"alfworld-2.1.2: {ALF212.resolve()} (next to ALFWorld): 134 files checked: OK",
        f"fever: {FEVER.resolve()} ($FEVER_DATA): 1 file checked: OK",
    ]


@needs_data
def test_check_reports_missing_and_mismatched(tmp_path):
    folder = tmp_path / "alfworld-2.1.2"
    shutil.copytree(ALF212 / "json_2.1.1", folder / "json_2.1.1", copy_function=shutil.copy)
    games = sorted(folder.glob("json_2.1.1/valid_unseen/*/*/game.tw-pddl"))
    games[0].unlink()
    games[1].chmod(0o644)
    games[1].write_text("{}")
    code, out, err = run("check", "alfworld-2.1.2", "--data-dir", str(folder))
    assert code == 1
    assert out.startswith(f"alfworld-2.1.2: {folder} (data_dir): 134 files checked: 1 missing, 1 mismatched (e.g. ")
    assert out.rstrip().endswith(": FAILED") and len(out.splitlines()) == 1
    assert err == "recap: error: data check: alfworld-2.1.2: 1 missing, 1 mismatched\n"


def test_check_a_missing_benchmark(isolated):
    code, out, err = run("check", "robotouille")
    assert code == 1
    assert out.startswith("robotouille: no folder found; run `recap data fetch robotouille`")
    assert len(err.splitlines()) == 1


def test_usage_errors_exit_2(tmp_path):
    for argv, text in (
        (["nope"], "invalid choice: 'nope'"),
        (["check", "blocksworld"], "invalid choice: 'blocksworld'"),
        (["list", "--data-dir", str(tmp_path)], "--data-dir names one benchmark's folder"),
        (["fetch", "--mirror", str(tmp_path / "missing")], "does not exist"),
        (["fetch", "--mirror", "ftp://example.org/x"], "use a folder, a file:// URL or an http(s):// URL"),
        ([], "required"),
    ):
        code, out, err = run(*argv)
        assert code == 2, argv
        assert len(err.splitlines()) == 1 and err.startswith("recap: error: data: ") and text in err, err
    code, out, err = run("fetch", "--help")
    assert code == 0 and "--mirror" in out and err == ""


# ---------------------------------------------------------------------------------------------
# fetch


def _robotouille_archive(path: Path, *, corrupt: str | None = None) -> None:
    """The upstream archive layout: robotouille-<commit>/..., with code files we must skip."""
    top = f"robotouille-{ROBOTOUILLE_COMMIT}"
    with tarfile.open(path, "w:gz", compresslevel=1) as tar:
        for p in sorted(ROB.rglob("*")):
            rel = p.relative_to(ROB).as_posix()
            if p.is_file() and rel.split("/")[0] in ("LICENSE", "domain", "environments", "agents", "conf"):
                payload = p.read_bytes()
                if rel == corrupt:
                    payload = payload.replace(b'"', b"'", 1)
                info = tarfile.TarInfo(f"{top}/{rel}")
                info.size = len(payload)
                tar.addfile(info, io.BytesIO(payload))
        code = b"print('engine code')\n"
        info = tarfile.TarInfo(f"{top}/robotouille/robotouille_env.py")
        info.size = len(code)
        tar.addfile(info, io.BytesIO(code))


def _alfworld_zip(path: Path, root: Path, pattern: str) -> None:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as zf:
        for p in sorted((root / "json_2.1.1").rglob(pattern)):
            zf.write(p, p.relative_to(root).as_posix())
        # a game of another split: not needed, must not be extracted
        zf.writestr(f"json_2.1.1/train/pick_and_place_simple-X-None-Y-1/trial_T1/{pattern}", "{}")


@pytest.fixture(scope="module")
def mirror(tmp_path_factory):
    assert ROB.is_dir() and ALF.is_dir() and ALF212.is_dir() and FEVER.is_dir(), f"the tests need the benchmark data in {SHARED}"
    folder = tmp_path_factory.mktemp("mirror")
    shutil.copy(FEVER / "paper_dev.jsonl", folder / "paper_dev.jsonl")
    _robotouille_archive(folder / f"{ROBOTOUILLE_COMMIT}.tar.gz")
    _alfworld_zip(folder / "json_2.1.1_json.zip", ALF, "traj_data.json")
    _alfworld_zip(folder / "json_2.1.1_pddl.zip", ALF, "initial_state.pddl")
    _alfworld_zip(folder / "json_2.1.1_tw-pddl.zip", ALF, "game.tw-pddl")
    _alfworld_zip(folder / "json_2.1.2_tw-pddl.zip", ALF212, "game.tw-pddl")
    for name in ("alfred.pddl", "alfred.twl2"):
        shutil.copy(ALF / "logic" / name, folder / name)
    return folder


def _corrupt_copy(mirror: Path, tmp_path: Path) -> Path:
    bad = tmp_path / "bad-mirror"
    shutil.copytree(mirror, bad)
    return bad


def test_fetch_everything_from_a_mirror_folder_then_check(isolated, mirror, tmp_path):
    dest = tmp_path / "data"
    code, out, err = run("fetch", "--mirror", str(mirror), "--dest", str(dest))
    assert (code, err) == (0, ""), err
    assert sorted(p.name for p in dest.iterdir()) == ["alfworld", "alfworld-2.1.2", "fever", "robotouille"]
    assert f"fever: {dest / 'fever'}: 1 file fetched and verified" in out
    # 88 downloaded + 206 generated (202 instances, a summary.json and a README.md per folder)
    assert f"robotouille: {dest / 'robotouille'}: 294 files fetched and verified" in out
    assert f"alfworld: {dest / 'alfworld'}: 404 files fetched and verified" in out
    assert "  generating instances/, instances_train/\n" in out
    assert "robotouille: note: instances/ and instances_train/ were generated here" in out
    # only the data paths the manifests list: no engine code, no other split
    assert not (dest / "robotouille" / "robotouille").exists()
    assert not (dest / "alfworld" / "json_2.1.1" / "train").exists()
    assert (dest / "alfworld" / "MANIFEST.sha256").read_text().count("\n") == 404

    code, out, err = run("check", "alfworld", "--data-dir", str(dest / "alfworld"))
    assert (code, out) == (0, f"alfworld: {dest / 'alfworld'} (data_dir): 404 files checked: OK\n")
    code, out, err = run("check", "alfworld-2.1.2", "--data-dir", str(dest / "alfworld-2.1.2"))
    assert code == 0 and out.endswith("134 files checked: OK\n")
    rob = dest / "robotouille"
    code, out, err = run("check", "robotouille", "--data-dir", str(rob))
    assert (code, err) == (0, "")
    assert out == (
        f"robotouille: {rob} (data_dir): 300 files checked: OK (206 of them generated by recap-eval) "
        "(6 optional files absent: trajectories/ (6): recorded on the real engine; only "
        "`recap env replay` and the tests read them)\n"
    )
    assert (rob / "MANIFEST.sha256").read_text().count("\n") == 294
    # the generated kitchens are the recorded ones, and the fetched folder plays
    for name in (
        "instances/synchronous/5_double_cheeseburger_336.json",
        "instances_train/synchronous_train/0_cheese_onion_sandwich_26.json",
    ):
        made, recorded = json.loads((rob / name).read_text()), json.loads((ROB / name).read_text())
        for key in ("used_seed", "generated_environment_json", "initial_observation", "num_goal_sets"):
            assert json.dumps(made[key]) == json.dumps(recorded[key]), (name, key)
    from workers.envs.robotouille import BENCHMARK

    env = BENCHMARK.make("robotouille/asynchronous/5_potato_soup@42", data_dir=str(rob_data.resolve_data_dir(rob)))
    assert (
        env.reset().observation
        == json.loads((ROB / "instances/asynchronous/5_potato_soup_42.json").read_text())["initial_observation"]
    )
    # a generated file that was edited no longer verifies
    edited = rob / "instances/asynchronous/5_potato_soup_42.json"
    edited.write_text(edited.read_text().replace('"seed": 42', '"seed": 43', 1))
    code, out, err = run("check", "robotouille", "--data-dir", str(rob))
    assert code == 1 and "300 files checked: 0 missing, 1 mismatched (e.g. instances/asynchronous/5_potato_soup_42.json)" in out
    # the recorded files (copied from a complete folder) verify against the other digest
    for name in ("instances", "instances_train"):
        shutil.rmtree(rob / name)
        (rob / name).symlink_to(ROB / name)
    code, out, err = run("check", "robotouille", "--data-dir", str(rob))
    assert code == 0 and out.startswith(f"robotouille: {rob} (data_dir): 300 files checked: OK (6 optional")


def test_fetch_into_the_cache_is_found_by_the_resolver(isolated, mirror):
    code, out, err = run("fetch", "alfworld", "--mirror", mirror.as_uri())
    assert (code, err) == (0, ""), err
    assert alf_games.resolve_data_dir() == (isolated["cache"] / "alfworld").resolve()
    assert alf_games.discover_games(alf_games.resolve_data_dir())  # the 134 games are listed
    code, out, err = run("fetch", "alfworld-2.1.2", "--mirror", mirror.as_uri())
    assert code == 0
    # the sibling rule finds the 2.1.2 folder next to the cached 2.1.1 one
    assert alf_games.resolve_data_dir_2_1_2(alf_games.resolve_data_dir()) == (isolated["cache"] / "alfworld-2.1.2").resolve()
    code, out, err = run("check", "alfworld")
    assert (
        code == 0 and out == f"alfworld: {(isolated['cache'] / 'alfworld').resolve()} (recap-eval cache): 404 files checked: OK\n"
    )
    # fetching again verifies what is there and writes nothing
    code, out, err = run("fetch", "alfworld", "--mirror", str(mirror))
    assert code == 0 and "is already there and verifies (404 files)" in out


def test_fetch_over_http(isolated, mirror, tmp_path):
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(mirror))
    handler.log_message = lambda *a, **k: None  # type: ignore[method-assign]
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        base = f"http://127.0.0.1:{server.server_address[1]}"
        code, out, err = run("fetch", "robotouille", "--mirror", base + "/", "--dest", str(tmp_path / "r"))
        assert (code, err) == (0, ""), err
        assert f"downloading {base}/{ROBOTOUILLE_COMMIT}.tar.gz" in out
        code, out, err = run("fetch", "alfworld-2.1.2", "--mirror", base + "/missing", "--dest", str(tmp_path / "a"))
        assert code == 1 and "HTTP 404" in err and len(err.splitlines()) == 1
        assert not (tmp_path / "a").exists()
    finally:
        server.shutdown()
        server.server_close()
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


def _leftovers(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*")) if root.exists() else []


def test_corrupted_mirror_fails_with_one_line_and_leaves_nothing(isolated, mirror, tmp_path):
    bad = _corrupt_copy(mirror, tmp_path)
    _robotouille_archive(bad / f"{ROBOTOUILLE_COMMIT}.tar.gz", corrupt="domain/robotouille.json")
    dest = tmp_path / "out" / "deep" / "robotouille"
    code, out, err = run("fetch", "robotouille", "--mirror", str(bad), "--dest", str(dest))
    assert code == 1
    assert len(err.splitlines()) == 1
    assert err.startswith("recap: error: data fetch: robotouille: domain/robotouille.json from ")
    assert "does not match the manifest" in err and err.rstrip().endswith("nothing was written")
    assert not (tmp_path / "out").exists()  # not even the parents it created

    # a truncated archive
    data = (mirror / "json_2.1.1_tw-pddl.zip").read_bytes()
    (bad / "json_2.1.1_tw-pddl.zip").write_bytes(data[: len(data) // 2])
    code, out, err = run("fetch", "alfworld", "--mirror", str(bad))
    assert code == 1 and len(err.splitlines()) == 1
    assert "json_2.1.1_tw-pddl.zip is not a readable zip archive" in err
    assert _leftovers(isolated["home"]) == []

    # a mirror without one of the files
    (bad / "alfred.twl2").unlink()
    shutil.copy(mirror / "json_2.1.1_tw-pddl.zip", bad / "json_2.1.1_tw-pddl.zip")
    code, out, err = run("fetch", "alfworld", "--mirror", str(bad), "--dest", str(tmp_path / "alf"))
    assert code == 1 and len(err.splitlines()) == 1 and "alfred.twl2 is not in the mirror" in err
    assert not (tmp_path / "alf").exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_existing_folder_is_verified_not_overwritten(isolated, mirror, tmp_path):
    dest = tmp_path / "alfworld-2.1.2"
    dest.mkdir()
    (dest / "mine.txt").write_text("keep me")
    code, out, err = run("fetch", "alfworld-2.1.2", "--mirror", str(mirror), "--dest", str(dest))
    assert code == 1 and "exists and does not verify (134 missing, 0 mismatched)" in err
    assert [p.name for p in dest.iterdir()] == ["mine.txt"]
    (dest / "mine.txt").unlink()  # an empty folder is filled
    code, out, err = run("fetch", "alfworld-2.1.2", "--mirror", str(mirror), "--dest", str(dest))
    assert code == 0 and (dest / "MANIFEST.sha256").is_file()


@needs_data
def test_missing_instance_says_why(tmp_path):
    folder = _robotouille_folder(tmp_path / "fetched")
    from workers.envs.robotouille import BENCHMARK

    with pytest.raises(
        DataNotFoundError,
        match="not stored upstream: `recap data fetch robotouille` generates "
        "instances/ and instances_train/ into a new folder, or copy them",
    ):
        BENCHMARK.make("robotouille/asynchronous/5_potato_soup@42", data_dir=str(folder))


def test_default_alfworld_urls_match_the_installed_downloader():
    """The 2.1.1 archives are ALFWorld's release assets, the 2.1.2 games the ones alfworld 0.4.2's
    own `alfworld-download` fetches: keep the constants in step with the installed script."""
    script = Path(sys.executable).parent / "alfworld-download"
    assert script.is_file(), f"alfworld's downloader is not installed beside {sys.executable}"
    text = script.read_text()
    constants = dict(re.findall(r'^(\w+_URL) = "([^"]+)"', text, re.MULTILINE))
    assert constants["JSON_FILES_URL"] == alf_folders.JSON_URL
    assert constants["PDDL_FILES_URL"] == alf_folders.PDDL_URL
    assert constants["TW_PDDL_FILES_URL"] == alf_folders.TW_PDDL_2_1_2_URL
    assert alf_folders.TW_PDDL_2_1_1_URL == alf_folders.PDDL_URL.replace("_pddl.zip", "_tw-pddl.zip")


@needs_data
def test_repository_manifests_match_the_data_folders_own():
    for name, folder in (("alfworld", ALF), ("alfworld-2.1.2", ALF212)):
        assert datacmd.read_manifest(datacmd.MANIFEST_DIR / f"{name}.sha256") == datacmd.read_manifest(folder / "MANIFEST.sha256")
    rob = datacmd.read_manifest(datacmd.MANIFEST_DIR / "robotouille.sha256")
    assert len(rob) == 300 and "README.md" not in rob
    assert {ROB_FOLDER.group_of(rel).prefix for rel in rob} == {g.prefix for g in ROB_FOLDER.groups}
    # the digests of generated files cover exactly the generated groups, and every one differs
    # from the recorded file's (those hold the real engine's build times)
    made = datacmd.read_manifest(datacmd.generated_manifest_file(ROB_FOLDER))
    assert set(made) == {rel for rel in rob if ROB_FOLDER.group_of(rel).generated}
    assert len(made) == 206 and all(made[rel] != rob[rel] for rel in made)


def test_generated_instances_that_do_not_match_their_digest_fail_the_fetch(isolated, mirror, tmp_path, monkeypatch):
    from workers.envs.robotouille import generator

    real = generator.write_instances

    def drifted(root: Path, dest: Path) -> list[str]:
        written = real(root, dest)
        path = dest / "instances/synchronous/3_burger_84.json"
        path.write_text(path.read_text() + " ")
        return written

    monkeypatch.setattr(generator, "write_instances", drifted)
    dest = tmp_path / "out" / "robotouille"
    code, out, err = run("fetch", "robotouille", "--mirror", str(mirror), "--dest", str(dest))
    assert code == 1 and len(err.splitlines()) == 1
    assert err.startswith(
        "recap: error: data fetch: robotouille: instances/synchronous/3_burger_84.json as "
        "generated here does not match robotouille-generated.sha256 (sha256 "
    )
    assert err.rstrip().endswith("the problem files, the generator or the engine changed; nothing was written")
    assert not (tmp_path / "out").exists()

    def broken(root: Path, dest: Path) -> list[str]:
        raise generator.GenerationFailed("no kitchen could be generated for seeds 42..141")

    monkeypatch.setattr(generator, "write_instances", broken)
    code, out, err = run("fetch", "robotouille", "--mirror", str(mirror), "--dest", str(dest))
    assert code == 1 and err == (
        "recap: error: data fetch: robotouille: cannot generate the Robotouille instances: no kitchen could be "
        "generated for seeds 42..141; nothing was written\n"
    )
    assert not (tmp_path / "out").exists()


def test_fetch_fever_verifies_the_claims_digest(isolated, tmp_path):
    good, bad = tmp_path / "good", tmp_path / "bad"
    good.mkdir()
    bad.mkdir()
    shutil.copy(FEVER / "paper_dev.jsonl", good / "paper_dev.jsonl")
    (bad / "paper_dev.jsonl").write_bytes((FEVER / "paper_dev.jsonl").read_bytes().replace(b"SUPPORTS", b"REFUTES", 1))
    code, out, err = run("fetch", "fever", "--mirror", str(bad), "--dest", str(tmp_path / "d1"))
    assert code == 1 and len(err.splitlines()) == 1 and err.startswith("recap: error: data fetch: fever: ")
    assert not (tmp_path / "d1" / "fever").exists()
    code, out, err = run("fetch", "fever", "--mirror", good.as_uri())
    assert (code, err) == (0, ""), err
    assert f"fever: {isolated['cache'] / 'fever'}: 1 file fetched and verified" in out
    assert fever_claims.resolve_data_dir() == (isolated["cache"] / "fever").resolve()
