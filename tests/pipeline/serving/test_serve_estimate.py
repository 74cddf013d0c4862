"""``recap estimate`` of a served model (pipeline/serving/throughput.py, pipeline/estimate.py): its
output tokens over its tokens/s, as replica-hours at their price, the figure's source printed -
given in the sweep (exact arithmetic), or measured by a probe that deploys the test double
through Ray Serve and takes it down (slow)."""

from __future__ import annotations

import io

import pytest
from rich.console import Console

from pipeline.estimate import estimate, render
from pipeline.spec import parse_spec
from pipeline.units import expand

SPEC = """run: est
output: /tmp/never-written
models:
  - model: offline/expert
    label: served-expert
    serve: {{replicas: 2, max_in_flight: {mif}{extra}}}
    prices: {{replica_hour: 36}}
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, instances: [blocksworld/5@1]}}]
workers: 4
"""


def _text(groups, plan) -> str:
    out = io.StringIO()
    render(plan, groups, [], Console(file=out, width=240, color_system=None))
    return out.getvalue()


def test_a_served_model_is_priced_by_the_replica_hours_of_its_output_tokens_at_the_sweeps_tokens_per_s():
    plan = expand(parse_spec(SPEC.format(mif=4, extra=", tokens_per_s: 10"), "sweep.yaml"))
    (g,) = estimate(plan)
    # blocksworld/5@1: 10 optimal steps, 40 allowed; ReAct 11 - 41 calls of 60 - 250 output tokens
    assert (g.calls.low, g.calls.high) == (11, 41) and (g.output.low, g.output.high) == (660, 10250)
    # 4 workers fill half of 2 replicas x 4 slots: 660 / (10 x 2 x 0.5) = 66 s held by 2 replicas
    # = 0.0367 replica-hours x $36 = $1.32; 10250 tokens: 1025 s, $20.50
    assert g.cost is not None and (g.cost.low, g.cost.high) == (pytest.approx(1.32), pytest.approx(20.5))
    assert g.throughput is not None and (g.throughput.tokens_per_s, g.throughput.source) == (10, "from the sweep")
    text = _text([g], plan)
    assert "1.32 - 20.50" in text and "total: 1 unit, 11 - 41 calls, $1.32 - $20.50" in text
    assert "served-expert: served, 10.0 output tokens/s a replica (from the sweep), 2 x $36/replica-hour, efficiency 0.50" in text


def test_a_served_model_without_tokens_per_s_has_no_price_and_says_how_to_get_one():
    plan = expand(parse_spec(SPEC.format(mif=1, extra=""), "sweep.yaml"))
    (g,) = estimate(plan)
    assert g.cost is None and g.throughput is None
    text = _text([g], plan)
    assert "no price" in text and "(plus models without a price)" in text
    assert "served-expert: served, no tokens/s: give serve.tokens_per_s or run recap estimate --probe" in text


@pytest.mark.parametrize("value", [0, -5, "fast"])
def test_a_tokens_per_s_that_is_not_a_positive_number_is_refused(value):
    from pipeline.errors import SpecError

    with pytest.raises(SpecError, match="tokens_per_s"):
        parse_spec(SPEC.format(mif=1, extra=f", tokens_per_s: {value}"), "sweep.yaml")


@pytest.mark.slow
def test_the_probe_deploys_the_test_double_measures_its_tokens_per_s_and_takes_it_down(ray_address, tmp_path, capsys):
    from pipeline.cli import main
    from pipeline.serving.service import serve_apps
    from pipeline.serving.throughput import PROBE_MAX_TOKENS, PROBE_PROMPT, PROBE_WAVES, probe
    from workers.serving.test_double import chat_answer

    text = SPEC.format(mif=2, extra=", engine_args: {latency_s: 0.5}")
    path = tmp_path / "sweep.yaml"
    path.write_text(text)
    assert main(["estimate", str(path), "--probe"]) == 0
    out = capsys.readouterr().out
    assert "(measured by probe), 2 x $36/replica-hour, efficiency 1.00" in out
    assert not [a for a in serve_apps() if a.startswith("recap-probe-")]  # taken down

    spec = parse_spec(text, "sweep.yaml")
    (measured,) = probe(spec).values()
    # each answer waits 0.5 s: 2 waves of 4 requests of c tokens take >= 1 s, so one replica of two
    # turns out at most 2 x 4 x c / 1 s / 2
    c = chat_answer({"model": "expert", "messages": [{"role": "user", "content": PROBE_PROMPT}], "max_tokens": PROBE_MAX_TOKENS})
    c = c["usage"]["completion_tokens"]
    assert measured.source == "measured by probe" and 0 < measured.tokens_per_s <= PROBE_WAVES * 4 * c / 1.0 / 2
    (g,) = estimate(expand(spec), {"served-expert": measured})
    # 4 workers fill 2 replicas x 2 slots: efficiency 1
    assert g.cost is not None and g.cost.high == pytest.approx(g.output.high / (measured.tokens_per_s * 2) * 2 * 36 / 3600)
    assert not [a for a in serve_apps() if a.startswith("recap-probe-")]
