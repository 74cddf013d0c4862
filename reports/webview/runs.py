"""The runs page's rows: one per run with its progress, spend and caps, and its sweep file with secrets redacted."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

from reports.webview.errors import BadRequest
from reports.webview.snapshot import Snapshot
from schemas.parts import read_run_file

_SECRET_KEY = re.compile(r"(key|token|secret|password|passwd|authorization|credential)", re.I)
_SECRET_VALUE = re.compile(
    r"\b(sk-[A-Za-z0-9_\-]{8,}|(?:AKIA|ASIA)[A-Z0-9]{12,}|[A-Za-z0-9_\-]{20,}\.[A-Za-z0-9_\-]{20,}\.[A-Za-z0-9_\-]{10,})\b"
)


def redact_spec(text: str) -> str:
    """The sweep file with any value under a key that names a secret replaced (``api_key_env``
    names a variable, not a key, and stays) and key-shaped strings masked anywhere."""
    out = []
    for line in text.splitlines():
        m = re.match(r"^(\s*-?\s*)([A-Za-z0-9_\-]+)(\s*:\s*)(.+)$", line)
        if m and _SECRET_KEY.search(m.group(2)) and m.group(2) != "api_key_env" and m.group(4).strip() not in ("", "null", "~"):
            line = f"{m.group(1)}{m.group(2)}{m.group(3)}<redacted>"
        out.append(_SECRET_VALUE.sub("<redacted>", line))
    return "\n".join(out) + ("\n" if text.endswith("\n") else "")


def _spec_caps(spec_yaml: str | None) -> dict[str, Any]:
    """The caps a sweep file set (run, episode limits, per model), by name; {} when it does not parse."""
    try:
        data = yaml.safe_load(spec_yaml or "") or {}
    except yaml.YAMLError:
        return {}
    if not isinstance(data, dict):
        return {}
    caps: dict[str, Any] = {}
    if data.get("run_cap_usd") is not None:
        caps["run_cap_usd"] = data["run_cap_usd"]
    limits = data.get("limits")
    if isinstance(limits, dict):
        caps.update({f"episode_{k}": v for k, v in limits.items()})
    for m in data.get("models") or []:
        if isinstance(m, dict) and m.get("cap_usd") is not None:
            caps[f"cap_usd[{m.get('label') or m.get('model')}]"] = m["cap_usd"]
    return caps


def runs(snap: Snapshot) -> list[dict[str, Any]]:
    """One row per run: name, folder, started, units planned / done, success, spend, caps."""
    base = {r["run_id"]: r for r in snap.named("runs").dicts()}
    cover_by: dict[str, dict[str, int]] = {}
    for r in snap.named("coverage").dicts():  # per run and arm: summed per run here
        c = cover_by.setdefault(r["run_id"], {})
        for k in _COVERAGE_COUNTS:
            if k in r:
                c[k] = c.get(k, 0) + int(r[k] or 0)
    spend = {
        r["run_id"]: r
        for r in snap.query("SELECT run_id, sum(cost_usd) AS spend_usd, count(*) AS calls FROM llm_calls GROUP BY run_id").dicts()
    }
    specs = {
        r["run_id"]: r["spec_yaml"]
        for r in snap.query("SELECT run_id, arg_max(spec_yaml, started_at) AS spec_yaml FROM run GROUP BY run_id").dicts()
    }
    folders = snap.query("SELECT run_dir, run_json_id FROM run_dirs ORDER BY run_dir").dicts()
    out = []
    seen = set()
    for f in folders:
        rid = f["run_json_id"]
        name = _run_name(Path(f["run_dir"]))
        ids = [rid] if rid else sorted(k for k in base if k not in seen)
        for run_id in ids:
            seen.add(run_id)
            b, c, s = base.get(run_id, {}), cover_by.get(run_id, {}), spend.get(run_id, {})
            out.append(
                {
                    "run_id": run_id,
                    "name": name,
                    "run_dir": f["run_dir"],
                    "started": b.get("first_started"),
                    "starts": b.get("starts", 0),
                    "host": b.get("host"),
                    "git_revision": b.get("git_revision"),
                    "planned": c.get("planned"),
                    "finished": c.get("finished"),
                    "successes": c.get("successes"),
                    "capped": c.get("capped"),
                    "not_started": c.get("not_started"),
                    "gave_up": c.get("gave_up", c.get("infra_failed")),
                    "units": b.get("units", 0),
                    "spend_usd": s.get("spend_usd") or 0.0,
                    "calls": s.get("calls", 0),
                    "caps": _spec_caps(specs.get(run_id)),
                    "has_spec": specs.get(run_id) is not None,
                }
            )
    return out


#: the unit counts of reports/sql/coverage.sql (gave_up was infra_failed before schema version 2)
_COVERAGE_COUNTS = ("planned", "finished", "successes", "capped", "gave_up", "infra_failed", "not_started")


def run_spec(snap: Snapshot, run_id: str) -> str:
    """The sweep file the run was started with (its latest session), secrets redacted; a 404 when none was recorded."""
    r = snap.query("SELECT arg_max(spec_yaml, started_at) AS s FROM run WHERE run_id = $r", {"r": run_id}).rows
    if not r or r[0][0] is None:
        raise BadRequest(f"no sweep file recorded for run {run_id!r}", 404)
    return redact_spec(r[0][0])


def _run_name(run_dir: Path) -> str:
    data = read_run_file(run_dir) or {}
    return str(data.get("run") or data.get("name") or run_dir.name)
