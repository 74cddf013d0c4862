"""Tool calls from a hostile provider (issue 35 item 6): each mode of the fake server's
``HOSTILE_CALL_MODES`` (arguments nested 200,000 deep as a string or inside the body, 5 MB of
arguments, two calls under one id, a null function, content beside the calls, ``finish_reason:
tool_calls`` with no call, arguments as an object, a 1 MB call id), played

* at the gateway, one call: the answer is the model's reply exactly (never a ``server_error``),
  its cost in the row, the answer and the ledger alike, never below the provider's bill;
* in an episode (ReCAP's tool mode, a toy repository): every call the reply made is in
  ``tool_calls`` (bounded rows), the episode not ended as infrastructure;
* against a small run cap, called until the budget refuses: the ledger never passes the cap;
* and the deep-arguments mode through ``recap run`` and ``recap resume`` of a coding sweep (a local
  sandbox): the unit ends ``call_cap``, the resume sends and pays nothing.

One check per mode and property: not infra, recorded, cost counted, cap held. The attacks, the
expected answers and rows are the unit tests' own (tests/workers/gateway/test_hostile_calls.py,
tests/pipeline/test_hostile_calls_run.py).
"""

from __future__ import annotations

import json
import os
from typing import Any

from tests.pipeline.chaos.harness import Lab, ScenarioResult

CAP_USD = 0.002


def hostile_calls(lab: Lab) -> ScenarioResult:
    from recap.llm import LLMError
    from schemas.labels import infra_failure
    from tests.workers.gateway.test_hostile_calls import (
        ROWS,
        config,
        hostile_episode,
        one_hostile_call,
        reply_matches,
        spend_hostile,
        table,
        tool_rows,
        true_bill_pico,
    )
    from workers.gateway.core import DeploymentGateway
    from workers.llm.litellm_setup import get_litellm
    from workers.llm.offline.fake_server import HOSTILE_CALL_MODES
    from workers.llm.pricing import pico_to_usd, usd_to_pico

    get_litellm()
    res = ScenarioResult("hostile tool calls")
    tried = held = 0
    worst_over = 0

    def check(name: str, ok: bool, detail: Any = "") -> None:
        nonlocal tried, held
        tried += 1
        held += bool(ok)
        res.check(name, ok, detail)

    for mode in HOSTILE_CALL_MODES:
        res.begin_run()
        try:
            server = lab.server()
            run_dir = lab.folder(f"hostilecalls/{mode}")
            (run_dir / "run.json").write_text(json.dumps({"run_id": f"hostile-{mode}"}))
            out, stats = one_hostile_call(server, run_dir, mode)
            result, rows, _ = hostile_episode(lab.server(), mode)
            check(
                f"{mode}: not infra (the call is the model's, the episode not infra_error)",
                reply_matches(mode, out) and infra_failure(result.end_reason, result.error) is None,
                (getattr(out, "kind", "reply"), result.end_reason),
            )
            check(f"{mode}: every call recorded in tool_calls, bounded", tool_rows(rows) == ROWS[mode], len(tool_rows(rows)))
            (row,) = table(run_dir, "llm_calls")
            check(
                f"{mode}: cost counted (row = answer = ledger > 0, >= the provider's bill)",
                row["cost_usd"] == out.cost_usd == stats["spent_usd"] > 0 and stats["spent_pico"] >= true_bill_pico(server),
                f"${row['cost_usd']:.6f}",
            )
            capped = lab.server()
            cap_dir = lab.folder(f"hostilecalls/{mode}-cap")
            (cap_dir / "run.json").write_text(json.dumps({"run_id": f"hostile-cap-{mode}"}))
            gw = DeploymentGateway(config(capped, params={"max_tokens": 64}), run_dir=cap_dir, run_cap_usd=CAP_USD)
            spent_out, cap_stats = spend_hostile(gw, mode)
            spent, bill = int(cap_stats["spent_pico"]), true_bill_pico(capped)
            worst_over = max(worst_over, spent - usd_to_pico(CAP_USD), bill - usd_to_pico(CAP_USD), 0)
            check(
                f"{mode}: run cap ${CAP_USD} held ({len(spent_out)} calls until refused)",
                isinstance(spent_out[-1], LLMError)
                and spent_out[-1].kind == "budget"
                and spent <= usd_to_pico(CAP_USD)
                and bill <= spent
                and cap_stats["overruns"] == 0,
                f"ledger ${pico_to_usd(spent):.6f}, provider ${pico_to_usd(bill):.6f}",
            )
        except Exception as exc:
            check(f"{mode}: the attack ran", False, f"{type(exc).__name__}: {exc}"[:300])
        res.end_run()

    # the case through the CLI: recap run, then recap resume
    res.begin_run()
    try:
        from tests.pipeline.test_hostile_calls_run import CALLS, KEY_ENV, expected_deep_rows, run_and_resume

        lab.ray_address()
        os.environ[KEY_ENV] = os.environ.get(KEY_ENV) or "not-a-secret"
        server = lab.server(fault_rates={"deepargs": 1.0})
        r = run_and_resume(lab.folder("hostilecalls/cli"), server)
        ends = [e[0] for e in r.episodes]
        check("deepargs via recap run: not infra (call_cap)", r.run_exit == 0 and ends == ["call_cap"], (r.run_exit, ends))
        check("deepargs via recap run: every call in tool_calls", r.tool_calls == expected_deep_rows(), len(r.tool_calls))
        check(
            "deepargs via recap run: cost counted (episode = calls = ledger >= bill)",
            r.sent == CALLS and abs(r.episodes[0][3] - r.calls_cost_usd) < 1e-12 and r.spent_pico >= r.bill_pico > 0,
            f"${pico_to_usd(r.spent_pico):.6f}",
        )
        check(
            "deepargs via recap resume: nothing sent or paid again",
            r.resume_exit == 0 and r.sent_after_resume == r.sent and r.spent_after_resume_pico == r.spent_pico,
            (r.sent, r.sent_after_resume),
        )
    except Exception as exc:
        check("deepargs via recap run: the attack ran", False, f"{type(exc).__name__}: {exc}"[:300])
    res.end_run()

    res.overspend_usd = pico_to_usd(worst_over)
    res.name = f"hostile tool calls ({len(HOSTILE_CALL_MODES)} modes + 1 run/resume)"
    res.notes.append(f"{held}/{tried} held")
    return res
