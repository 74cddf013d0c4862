"""Hostile sweep files and flags: bounded values, paths resolved once, no YAML bombs or duplicate
keys, safe labels, one spelling per instance, checked Ray addresses and object-store outputs.

Every refusal is checked end to end through ``recap run``: exit status 2, exactly one line on
stderr (``recap: error: ...``), no output folder created and nothing else written.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.errors import SpecError
from pipeline.spec import MAX_SPEC_BYTES, check_output_location, parse_spec, with_overrides
from pipeline.store import PLAN_FILE, SPEC_FILE, RunStore
from pipeline.units import MAX_UNITS, canonical_instance_id, expand

REPO = Path(__file__).resolve().parents[3]

GOOD = """run: hardening
output: {out}
models:
  - model: offline/expert
methods:
  - method: recap
environments:
  - benchmark: blocksworld
    tasks: ["3"]
seeds: [0]
"""
MODEL = "  - model: offline/expert\n"
ENV = '    tasks: ["3"]\n'


def _snapshot(d: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(d)): (p.stat().st_size, p.stat().st_mtime_ns) for p in d.rglob("*")}


def run_cli(
    tmp_path: Path, capsys, spec_text: str | bytes | None, *extra: str, spec_path: str | None = None
) -> tuple[int, list[str], Path]:
    out = tmp_path / "out"
    spec = tmp_path / "sweep.yaml"
    if spec_text is not None:
        if isinstance(spec_text, bytes):
            spec.write_bytes(spec_text)
        else:
            spec.write_text(spec_text.replace("{out}", str(out)))
    capsys.readouterr()
    code = main(["run", spec_path or str(spec), "--progress", "off", *extra])
    captured = capsys.readouterr()
    return code, captured.err.strip().splitlines(), out


def assert_refused(
    tmp_path: Path, capsys, spec_text: str | bytes | None, expect: str, *extra: str, spec_path: str | None = None
) -> str:
    before = _snapshot(tmp_path)
    before.pop("sweep.yaml", None)
    code, err, out = run_cli(tmp_path, capsys, spec_text, *extra, spec_path=spec_path)
    assert code == 2, err
    assert len(err) == 1, err
    assert err[0].startswith("recap: error: "), err
    assert expect in err[0], err[0]
    assert err[0].isprintable(), err[0]
    assert not out.exists()
    after = _snapshot(tmp_path)
    after.pop("sweep.yaml", None)
    assert after == before
    return err[0]


def edit(old: str, new: str, text: str = GOOD) -> str:
    assert old in text, old
    return text.replace(old, new, 1)


def model_with(extra: str) -> str:
    return edit(MODEL, MODEL + "".join(f"    {line}\n" for line in extra.splitlines()))


def top(extra: str) -> str:
    return GOOD + extra + "\n"


# --------------------------------------------------------------------------------------------
# 1. values that reach a table are bounded; no booleans for numbers; no non-finite floats
# --------------------------------------------------------------------------------------------
BOUNDED = [
    ("seed beyond int64", edit("seeds: [0]", "seeds: [0, 9223372036854775808]"), "seeds[1]: integer out of range"),
    (
        "seed beyond the documented range",
        edit("seeds: [0]", "seeds: [2147483648]"),
        "seeds[0]: 2147483648 is out of range [0, 2147483647]",
    ),
    ("negative seed", edit("seeds: [0]", "seeds: [-1]"), "seeds[0]: -1 is out of range [0, 2147483647]"),
    ("boolean seed", edit("seeds: [0]", "seeds: [true]"), "seeds[0]: must be a number, not true/false"),
    ("boolean workers", top("workers: true"), "workers: must be a number, not true/false"),
    ("absurd workers", top("workers: 1000000"), "workers: 1000000 is out of range [1, 1024]"),
    ("absurd max_attempts", top("max_attempts: 100000"), "max_attempts: 100000 is out of range [1, 100]"),
    ("boolean max_attempts", top("max_attempts: yes"), "max_attempts: must be a number"),
    ("rpm beyond int64", model_with("rpm: 99999999999999999999999"), "models[0].rpm: integer out of range"),
    ("absurd tpm", model_with("tpm: 1000000000000000"), "models[0].tpm: 1000000000000000 is out of range [1, 100000000000]"),
    ("boolean concurrency", model_with("concurrency: true"), "models[0].concurrency: must be a number"),
    ("absurd retries", model_with("retries: 100000"), "models[0].retries: 100000 is out of range [0, 100]"),
    ("nan timeout", model_with("timeout_s: .nan"), "models[0].timeout_s: must be a finite number"),
    ("infinite window", model_with("window_s: .inf"), "models[0].window_s: must be a finite number"),
    ("nan temperature", model_with("params: {temperature: .nan}"), "models[0].params.temperature: must be a finite number"),
    ("infinite temperature", model_with("params: {temperature: -.inf}"), "models[0].params.temperature: must be a finite number"),
    (
        "params seed beyond int64",
        model_with("params: {seed: 18446744073709551616}"),
        "models[0].params.seed: integer out of range",
    ),
    (
        "nan test-double option",
        model_with("options: {invalid_action_rate: .nan}"),
        "models[0].options.invalid_action_rate: must be a finite number",
    ),
    (
        "nan method setting",
        edit("  - method: recap\n", "  - method: recap\n    settings: {window: .nan}\n"),
        "methods[0].settings.window: must be a finite number",
    ),
    ("infinite cap", model_with("cap_usd: .inf"), "models[0].cap_usd: must be a finite number"),
    ("absurd cap", model_with("cap_usd: 1.0e12"), "models[0].cap_usd: 1000000000000 is out of range [0, 1000000]"),
    ("boolean cap", model_with("cap_usd: true"), "models[0].cap_usd: must be a number"),
    ("nan price", model_with("prices: {input: .nan, output: 1}"), "models[0].prices.input: must be a finite number"),
    (
        "overflowing price",
        model_with("prices: {input: 1, output: 1e400}"),
        "models[0].prices.output: Input should be a finite number",
    ),
    (
        "absurd price",
        model_with("prices: {input: 1, output: 1000000}"),
        "models[0].prices.output: 1000000 is out of range [0, 10000]",
    ),
    ("infinite run cap", top("run_cap_usd: .inf"), "run_cap_usd: must be a finite number"),
    ("nan step multiplier", top("step_multiplier: .nan"), "step_multiplier: must be a finite number"),
    ("absurd step multiplier", top("step_multiplier: 1.0e9"), "step_multiplier: 1000000000 is out of range [0.1, 1000]"),
    (
        "per-episode token limit beyond int64",
        top("limits: {tokens: 100000000000000000000}"),
        "limits.tokens: integer out of range",
    ),
    (
        "absurd per-episode call limit",
        top("limits: {llm_calls: 10000000000}"),
        "limits.llm_calls: 10000000000 is out of range [1, 1000000]",
    ),
    ("boolean call limit", top("limits: {llm_calls: true}"), "limits.llm_calls: must be a number"),
    ("nan per-episode dollar limit", top("limits: {usd: .nan}"), "limits.usd: must be a finite number"),
    (
        "absurd environment limit",
        edit(ENV, ENV + "    limit: 10000000000\n"),
        "environments[0].limit: 10000000000 is out of range [1, 100000]",
    ),
    ("nan worker cpus", top("ray: {worker_cpus: .nan}"), "ray.worker_cpus: must be a finite number"),
    (
        "absurd object store",
        top("ray: {object_store_mb: 100000000000}"),
        "ray.object_store_mb: 100000000000 is out of range [64, 1048576]",
    ),
    ("boolean num_cpus", top("ray: {num_cpus: true}"), "ray.num_cpus: must be a number"),
    (
        "nan inside an environment option",
        edit(ENV, ENV + "    options: {step_multiplier: .nan}\n"),
        "environments[0].options.step_multiplier: must be a finite number",
    ),
]


@pytest.mark.parametrize("text, expect", [c[1:] for c in BOUNDED], ids=[c[0] for c in BOUNDED])
def test_unbounded_values_are_refused(tmp_path, capsys, text, expect):
    assert_refused(tmp_path, capsys, text, f"sweep.yaml: {expect}")


def test_the_documented_upper_bounds_are_accepted(tmp_path):
    text = (
        model_with(
            "rpm: 10000000\ntpm: 100000000000\nconcurrency: 10000\nretries: 100\ntimeout_s: 900\nwindow_s: 86400\n"
            "cap_usd: 1000000\nprices: {input: 10000, output: 10000}"
        )
        + "workers: 1024\nmax_attempts: 100\nstep_multiplier: 1000\nrun_cap_usd: 1000000\n"
        + "limits: {llm_calls: 1000000, tokens: 10000000000, usd: 1000000}\n"
    )
    spec = parse_spec(edit("seeds: [0]", "seeds: [0, 2147483647]", text).replace("{out}", str(tmp_path / "o")), "sweep.yaml")
    assert spec.sampling_seeds == [0, 2147483647] and spec.models[0].tpm == 10**11


@pytest.mark.parametrize(
    "flags, expect",
    [
        (("--run-cap", "nan"), "command line: run_cap_usd: Input should be a finite number"),
        (("--run-cap", "inf"), "command line: run_cap_usd: Input should be a finite number"),
        (("--run-cap", "1e300"), "command line: run_cap_usd: 1e+300 is out of range [0, 1000000]"),
        (("--workers", "99999999999999999999"), "command line: workers: 99999999999999999999 is out of range [1, 1024]"),
        (("--address", "not-an-address"), "command line: ray.address: must be auto, host:port or ray://host:port"),
    ],
    ids=["run-cap nan", "run-cap inf", "run-cap huge", "workers huge", "address"],
)
def test_flags_are_bounded_like_the_file(tmp_path, capsys, flags, expect):
    assert_refused(tmp_path, capsys, GOOD, expect, *flags)


def test_a_run_folder_is_not_changed_by_a_refused_resume(tmp_path, capsys):
    """resume re-reads the run's spec.yaml: an edited copy with a duplicate key or a nan is one
    line, and the folder keeps every byte."""
    out = tmp_path / "out"
    text = GOOD.replace("{out}", str(out))
    store = RunStore(out)
    store.create_identity("hardening")
    store.write_text(PLAN_FILE, expand(parse_spec(text)).to_json() + "\n")
    for bad in (
        model_with("cap_usd: 1\ncap_usd: 9").replace("{out}", str(out)),
        top("step_multiplier: .nan").replace("{out}", str(out)),
    ):
        store.write_text(SPEC_FILE, bad)
        before = _snapshot(out)
        capsys.readouterr()
        assert main(["resume", str(out), "--progress", "off"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"recap: error: {out}/spec.yaml: "), err
        assert _snapshot(out) == before


# --------------------------------------------------------------------------------------------
# 2. paths resolved once; object-store outputs checked up front
# --------------------------------------------------------------------------------------------
def test_output_is_expanded_and_made_absolute_once(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.chdir(tmp_path)
    assert parse_spec(GOOD.replace("{out}", "~/runs/x")).output == str(tmp_path / "home" / "runs" / "x")
    assert parse_spec(GOOD.replace("{out}", "runs/../y")).output == str(tmp_path / "y")
    spec = parse_spec(GOOD.replace("{out}", "runs/x"))
    assert spec.output == str(tmp_path / "runs" / "x")
    # an override (recap run --output) is resolved the same way, and a resolved path stays as it is
    assert with_overrides(spec, output="~/other").output == str(tmp_path / "home" / "other")
    assert with_overrides(spec, workers=2).output == spec.output
    # every component then sees the same string: the run store, the units' env options
    assert RunStore(spec.output).location == str(tmp_path / "runs" / "x")


def test_data_dir_options_and_a_replay_folder_are_resolved(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.chdir(tmp_path)
    text = edit(
        ENV, ENV + "    options: {data_dir: ~/data, data_dir_2_1_2: rel/212, cache_dir: ./c, engine: ours, version: 2.1.1}\n"
    )
    text = edit(MODEL, "  - model: offline/replay\n    api_base: ~/runs/old\n" + MODEL, text)
    spec = parse_spec(text.replace("{out}", "o"))
    assert spec.environments[0].options == {
        "data_dir": str(tmp_path / "data"),
        "data_dir_2_1_2": str(tmp_path / "rel" / "212"),
        "cache_dir": str(tmp_path / "c"),
        "engine": "ours",
        "version": "2.1.1",
    }
    assert spec.models[0].api_base == str(tmp_path / "runs" / "old")


def test_a_tilde_output_is_one_folder_for_the_whole_run(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    (tmp_path / "home").mkdir()
    code, err, _ = run_cli(tmp_path, capsys, GOOD.replace("{out}", "~/runs/tilde"), "--dry-run")
    assert (code, err) == (0, [])
    assert not (tmp_path / "home" / "runs").exists()
    assert not Path("~").exists()


@pytest.mark.parametrize(
    "output, expect",
    [
        ("ftp://host/runs/x", "output: unknown URI scheme 'ftp'"),
        ("s3://", "output: 's3://' names no bucket or container"),
        ("file://relative/path", "output: a file:// URI needs an absolute path"),
    ],
)
def test_malformed_output_uris_are_refused(tmp_path, capsys, output, expect):
    assert_refused(tmp_path, capsys, GOOD.replace("{out}", output), expect)


def test_an_unreachable_object_store_endpoint_fails_fast(tmp_path, capsys):
    """A closed port stands for 'no network': refused in one line, in well under a second."""
    t0 = time.monotonic()
    line = assert_refused(
        tmp_path,
        capsys,
        GOOD.replace("{out}", "s3://bucket/runs/x?endpoint_override=127.0.0.1:1&scheme=http"),
        "sweep.yaml: output s3://bucket/runs/x?endpoint_override=127.0.0.1:1&scheme=http cannot be used: cannot connect to 127.0.0.1:1",
    )
    assert time.monotonic() - t0 < 10, line


@pytest.mark.parametrize("uri", ["s3://recap-no-such-bucket-7f3a/runs/x", "gs://recap-no-such-bucket-7f3a/runs/x"])
def test_a_cloud_output_without_network_or_credentials_is_one_line_and_bounded(tmp_path, capsys, monkeypatch, uri):
    """Without network (or credentials, or the bucket) the check fails; with them it would list
    the folder. Either way: one line, no folder, bounded in time (never a hang)."""
    monkeypatch.setenv("RECAP_STORE_CHECK_TIMEOUT_S", "8")
    for var in ("AWS_ENDPOINT_URL", "AWS_ENDPOINT_URL_S3", "STORAGE_EMULATOR_HOST"):
        monkeypatch.delenv(var, raising=False)
    t0 = time.monotonic()
    assert_refused(tmp_path, capsys, GOOD.replace("{out}", uri), f"sweep.yaml: output {uri} cannot be")
    assert time.monotonic() - t0 < 30


def test_status_and_resume_of_an_unreachable_store_are_one_line(tmp_path, capsys):
    uri = "s3://bucket/runs/x?endpoint_override=127.0.0.1:1&scheme=http"
    for cmd in ("status", "resume"):
        capsys.readouterr()
        assert main([cmd, uri]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"recap: error: output {uri} cannot be used"), err


def test_local_and_file_outputs_need_no_check():
    check_output_location("/tmp/some/folder")
    check_output_location("file:///tmp/some/folder")
    with pytest.raises(SpecError, match="unknown URI scheme 'ftp'"):
        check_output_location("ftp://x/y")


# --------------------------------------------------------------------------------------------
# 3. specs that would exhaust memory or hang
# --------------------------------------------------------------------------------------------
BOMB = """run: bomb
output: {out}
models:
  - model: offline/expert
    options: &a0 {seed: 1}
methods: [{method: recap}]
environments: [{benchmark: blocksworld, tasks: ["3"]}]
""" + "".join(
    f"x{i}: &a{i} [*a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}]\n"
    for i in range(1, 12)
)


@pytest.mark.parametrize(
    "text, expect",
    [
        (BOMB, "sweep.yaml: YAML anchors are not allowed (&a0 at line 5)"),
        (
            edit(ENV, ENV + "    options: {data_dir: *nowhere}\n"),
            "sweep.yaml: YAML aliases are not allowed (*nowhere at line 10)",
        ),
        (model_with("options: {seed: 1}") + "other: {<<: {seed: 2}}\n", "YAML merge keys (<<) are not allowed (line 12)"),
        (model_with("label: " + "L" * 50_000), "sweep.yaml: a value of 50000 characters at line 5; at most 4096"),
        (model_with("label: " + "L" * 300), "sweep.yaml: models[0].label: String should have at most 200 characters"),
        (edit("run: hardening", "run: " + "r" * 201), "sweep.yaml: run: String should have at most 200 characters"),
        (
            edit("- model: offline/expert", "- model: offline/" + "m" * 2100),
            "sweep.yaml: models[0].model: String should have at most 2000 characters",
        ),
        (model_with("api_key_env: " + "K" * 300), "sweep.yaml: models[0].api_key_env: String should have at most 200 characters"),
        (top("deep: " + "[" * 40 + "]" * 40), "sweep.yaml: nested deeper than 16 levels at line 11"),
        (top("big: " + "9" * 4000), "sweep.yaml: big: integer out of range"),
    ],
    ids=[
        "alias bomb",
        "alias",
        "merge key",
        "huge scalar",
        "long label",
        "long run name",
        "long model",
        "long key variable",
        "deep nesting",
        "huge integer",
    ],
)
def test_yaml_bombs_and_huge_values_are_refused(tmp_path, capsys, text, expect):
    assert_refused(tmp_path, capsys, text, expect)


def test_a_huge_sweep_file_is_refused_without_reading_it_all(tmp_path, capsys):
    body = GOOD + "# " + "x" * (MAX_SPEC_BYTES + 10) + "\n"
    assert_refused(tmp_path, capsys, body, "a sweep file may be at most 1 MiB")


@pytest.mark.parametrize("path", ["/dev/zero", "/dev/urandom"])
def test_a_device_as_the_sweep_file_is_refused(tmp_path, capsys, path):
    if not os.path.exists(path):
        pytest.skip(f"no {path}")
    assert_refused(tmp_path, capsys, None, f"sweep file '{path}' cannot be read: not a regular file", spec_path=path)


def test_a_fifo_as_the_sweep_file_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "sweep.yaml"
    os.mkfifo(fifo)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    r = subprocess.run(
        [sys.executable, "-m", "pipeline.cli", "run", str(fifo)],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
        stdin=subprocess.DEVNULL,
    )
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [
        f"recap: error: sweep file '{fifo}' cannot be read: not a regular file (a device, FIFO or socket)"
    ]


def test_a_folder_and_a_binary_file_as_the_sweep_file(tmp_path, capsys):
    assert_refused(tmp_path, capsys, None, "cannot be read: it is a folder", spec_path=str(tmp_path))
    assert_refused(tmp_path, capsys, b"run: x\n\xff\xfe\x00", "cannot be read: not UTF-8 text (byte 0xff at offset 7)")


def test_a_sweep_that_expands_to_too_many_units_is_refused(tmp_path, capsys):
    seeds = ", ".join(str(i) for i in range(10_000))
    text = edit("seeds: [0]", f"seeds: [{seeds}]", edit(ENV, '    tasks: ["all"]\n'))
    text = edit("  - method: recap\n", "  - method: recap\n  - method: react\n  - method: act\n", text)
    assert 9 * 3 * 10_000 > MAX_UNITS
    assert_refused(
        tmp_path, capsys, text, "units (9 instances x 3 methods x 1 models x 10000 sampling seeds); at most 200,000 per run"
    )


# --------------------------------------------------------------------------------------------
# 4. duplicate keys at any depth
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "text, expect",
    [
        (model_with("cap_usd: 1\ncap_usd: 100"), "recap: error: sweep.yaml: duplicate key 'cap_usd' at line 6 (first at line 5)"),
        (top("workers: 2\nworkers: 8"), "recap: error: sweep.yaml: duplicate key 'workers' at line 12 (first at line 11)"),
        (
            model_with("params: {temperature: 0.1, temperature: 1.5}"),
            "recap: error: sweep.yaml: duplicate key 'temperature' at line 5",
        ),
        (
            model_with("prices:\n  input: 1\n  output: 2\n  input: 0.01"),
            "recap: error: sweep.yaml: duplicate key 'input' at line 8 (first at line 6)",
        ),
        (top("methods:\n  - method: react"), "recap: error: sweep.yaml: duplicate key 'methods' at line 11 (first at line 5)"),
        (
            edit(ENV, ENV + "    options: {data_dir: /a}\n    options: {data_dir: /b}\n"),
            "duplicate key 'options' at line 11 (first at line 10)",
        ),
    ],
    ids=["model cap", "top level", "flow mapping", "nested price", "a whole list", "env options"],
)
def test_duplicate_keys_are_refused(tmp_path, capsys, text, expect):
    line = assert_refused(tmp_path, capsys, text, expect)
    assert line.startswith(expect) or expect in line


# --------------------------------------------------------------------------------------------
# 5. labels and names: a safe character set; user strings printed without markup
# --------------------------------------------------------------------------------------------
LABELS = [
    "[bold]x[/]",
    "[link=https://example.com]click[/link]",
    "model [/]",
    "two\nlines",
    "esc\x1b[31mred",
    "bell\x07",
    "rtl\u202eoverride",
    "tab\there",
    " padded",
    "back\\slash",
]


@pytest.mark.parametrize("label", LABELS, ids=[repr(x) for x in LABELS])
def test_unsafe_labels_are_refused(tmp_path, capsys, label):
    import json

    quoted = json.dumps(label)  # a YAML double-quoted scalar
    line = assert_refused(tmp_path, capsys, model_with(f"label: {quoted}"), "sweep.yaml: models[0].label: ")
    assert "\x1b" not in line and "\u202e" not in line
    line = assert_refused(
        tmp_path,
        capsys,
        edit("  - method: recap\n", f"  - method: recap\n    label: {quoted}\n"),
        "sweep.yaml: methods[0].label: ",
    )


@pytest.mark.parametrize("run", ["[bold]r", "r\x1b", "r n", "r/../x"])
def test_unsafe_run_names_are_refused(tmp_path, capsys, run):
    import json

    assert_refused(
        tmp_path, capsys, edit("run: hardening", f"run: {json.dumps(run)}"), "sweep.yaml: run: must be letters, digits"
    )


def test_ordinary_labels_are_accepted(tmp_path):
    text = model_with('label: "gpt-4o mini (t=0.2) @eu: v1.0/b+c, #2 50%"')
    assert parse_spec(text.replace("{out}", str(tmp_path))).models[0].name == "gpt-4o mini (t=0.2) @eu: v1.0/b+c, #2 50%"


@pytest.mark.parametrize("model", ["offline/[bold]x", "openai/gpt 4o", "openai/gpt\x1b"], ids=["bracket", "space", "escape"])
def test_unsafe_model_strings_are_refused(tmp_path, capsys, model):
    import json

    assert_refused(
        tmp_path,
        capsys,
        edit("- model: offline/expert", f"- model: {json.dumps(model)}"),
        "sweep.yaml: models[0].model: must be a litellm model string",
    )


def test_control_characters_in_other_strings_are_refused_and_escaped(tmp_path, capsys):
    line = assert_refused(
        tmp_path, capsys, edit(ENV, '    tasks: ["3\\e[2J"]\n'), "environments[0].tasks[0]: must not contain control characters"
    )
    assert "\x1b" not in line and "\\x1b" in line


def test_markup_in_user_strings_is_printed_as_is(tmp_path, capsys):
    """A folder name with Rich markup in it: the plan line prints it literally (it used to raise
    MarkupError on '[/]' and swallow '[bold]')."""
    out = tmp_path / "[bold]odd[/] [/]folder"
    code, err, _ = run_cli(tmp_path, capsys, GOOD.replace("{out}", str(out)), "--dry-run")
    assert (code, err) == (0, [])
    code = main(["run", str(tmp_path / "sweep.yaml"), "--dry-run"])
    assert code == 0
    assert f"-> {out}  (models:" in capsys.readouterr().out
    assert not out.exists()


# --------------------------------------------------------------------------------------------
# 6. one instance, one spelling
# --------------------------------------------------------------------------------------------
def test_two_spellings_of_a_blocksworld_instance_are_one_unit(tmp_path):
    text = edit(
        ENV,
        '    tasks: ["3"]\n    instances: [blocksworld/3@01, blocksworld/03@1, blocksworld/3@0002]\n'
        + "  - benchmark: blocksworld\n    instances: [blocksworld/4@7, blocksworld/004@007]\n",
    )
    plan = expand(parse_spec(text.replace("{out}", str(tmp_path))))
    assert [u.instance_id for u in plan.units] == ["blocksworld/3@1", "blocksworld/3@2", "blocksworld/3@3", "blocksworld/4@7"]


def test_canonical_instance_ids():
    assert canonical_instance_id("blocksworld/03@001") == "blocksworld/3@1"
    assert canonical_instance_id("blocksworld/3@0") == "blocksworld/3@0"
    with pytest.raises(Exception, match="seed must be within 0..2147483647"):
        canonical_instance_id("blocksworld/3@99999999999999999999999")

    class Env:
        instance_id = "robotouille/asynchronous/5_potato_soup@42"

    assert canonical_instance_id("robotouille/asynchronous/5_potato_soup@042", Env()) == Env.instance_id
    assert canonical_instance_id("alfworld/x", Env()) == "alfworld/x"  # another benchmark's id is not taken


def test_two_spellings_of_a_robotouille_instance_are_one_unit(tmp_path):
    from workers.envs.robotouille.data import resolve_data_dir

    resolve_data_dir(None)  # the test environment has the data (../shared/data or ROBOTOUILLE_DATA)
    text = edit(
        "  - benchmark: blocksworld\n" + ENV,
        "  - benchmark: robotouille\n    instances: [robotouille/asynchronous/5_potato_soup@42, "
        "robotouille/asynchronous/5_potato_soup@042]\n  - benchmark: robotouille\n    tasks: [asynchronous/5_potato_soup@0042]\n",
    )
    plan = expand(parse_spec(text.replace("{out}", str(tmp_path))))
    assert [u.instance_id for u in plan.units] == ["robotouille/asynchronous/5_potato_soup@42"]


# --------------------------------------------------------------------------------------------
# 7. ray.address
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "address",
    [
        "nohost",
        "host:0",
        "host:65536",
        "ray://",
        "http://10.0.0.5:6379",
        "10.0.0.5:port",
        "[zz::1]:6379",
        "host name:6379",
        "10.0.0.5:6379/x",
        "-bad-:1",
    ],
)
def test_malformed_ray_addresses_are_refused(tmp_path, capsys, address):
    import json

    assert_refused(
        tmp_path,
        capsys,
        top(f"ray: {{address: {json.dumps(address)}}}"),
        "sweep.yaml: ray.address: must be auto, host:port or ray://host:port",
    )


@pytest.mark.parametrize(
    "address",
    ["auto", "local", "127.0.0.1:6379", "ray://10.0.0.5:10001", "[::1]:6379", "head-node.internal:6379", "ray://[fe80::1]:10001"],
)
def test_well_formed_ray_addresses_are_accepted(tmp_path, address):
    import json

    assert parse_spec(top(f"ray: {{address: {json.dumps(address)}}}").replace("{out}", str(tmp_path))).ray.address == address


def test_an_unreachable_ray_address_is_one_line_before_any_write(tmp_path, capsys):
    t0 = time.monotonic()
    assert_refused(tmp_path, capsys, GOOD, "ray.address 127.0.0.1:1: cannot connect to 127.0.0.1:1", "--address", "127.0.0.1:1")
    assert_refused(tmp_path, capsys, top("ray: {address: 'ray://127.0.0.1:1'}"), "ray.address ray://127.0.0.1:1: cannot connect")
    assert time.monotonic() - t0 < 10
    # --dry-run does not connect
    code, err, out = run_cli(tmp_path, capsys, GOOD, "--dry-run", "--address", "127.0.0.1:1")
    assert (code, err, out.exists()) == (0, [], False)


def test_status_of_an_old_run_whose_labels_hold_markup_does_not_crash(tmp_path, capsys):
    """A run folder written before labels were restricted: its plan names a method '[/]old' and
    a model '[bold]m'. recap status prints them (markup off) instead of dying on every call."""
    import json

    out = tmp_path / "old"
    store = RunStore(out)
    store.create_identity("old")
    units = [
        {
            "unit_id": "u1",
            "key": "blocksworld/3@1 | [/]old | [bold]m | seed 0",
            "instance_id": "blocksworld/3@1",
            "method": "[/]old",
            "model": "[bold]m",
            "seed": 0,
        }
    ]
    store.write_text(PLAN_FILE, json.dumps({"hash_version": 1, "units": units}))
    capsys.readouterr()
    assert main(["status", str(out)]) == 0
    printed = capsys.readouterr()
    assert "[/]old" in printed.out and "[bold]m" in printed.out, printed.out
    assert printed.err == ""


@pytest.mark.parametrize("value, kind", [("2024-01-01", "date"), ("!!binary aGVsbG8=", "bytes"), ("!!set {x, y}", "set")])
def test_only_plain_yaml_values_reach_free_form_mappings(tmp_path, capsys, value, kind):
    assert_refused(
        tmp_path,
        capsys,
        model_with(f"params: {{stop: {value}}}"),
        f"sweep.yaml: models[0].params.stop: a YAML {kind} is not allowed here; quote it to make it a string",
    )


# --------------------------------------------------------------------------------------------
# credentials never travel in an api_base (they would be stored with the spec)
@pytest.mark.parametrize(
    "url",
    [
        "https://user:s3cret@api.example.com/v1",
        "https://api.example.com/v1?api_key=s3cret",
        "http://127.0.0.1:8000/v1?token=s3cret&x=1",
    ],
)
def test_api_base_with_credentials_is_refused(tmp_path, capsys, url):
    text = GOOD.replace(
        "- model: offline/expert", f"- model: openai/gpt-4o-mini\n    api_base: {url}\n    api_key_env: OPENAI_API_KEY", 1
    )
    line = assert_refused(tmp_path, capsys, text, "must not carry credentials")
    assert "s3cret" not in line


def test_progress_shows_a_provider_pause_and_escapes_markup():
    from pipeline.backend import RateStats
    from pipeline.progress import ProgressView, Snapshot, paused_text, status_line

    now = 1_000_000.0
    assert paused_text(None, now) == "" and paused_text(now - 1, now) == ""
    assert paused_text(now + 90, now).startswith("  paused until ")
    snap = Snapshot(
        total=2,
        done=1,
        success=1,
        running=1,
        spend_usd=0.5,
        run_cap_usd=None,
        eta_s=None,
        rates={"[bold]m[/]": RateStats(rpm=1, rpm_limit=10, paused_until=__import__("time").time() + 600)},
    )
    assert "[bold]m[/]: rpm" in status_line(snap) and "paused until" in status_line(snap)
    from rich.console import Console

    console = Console(record=True, width=200)
    console.print(ProgressView("off", title="run [red]x[/")._render(snap))
    shown = console.export_text()
    assert "[bold]m[/]" in shown and "run [red]x[/" in shown and "paused until" in shown
