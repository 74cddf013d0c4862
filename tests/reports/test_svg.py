"""The hand-written SVG charts: the legend never covers a bar, however many arms; a bar of 0 is
visible (a mark on the axis and its value label); the chart grows to hold its legend. Geometry is
read back by parsing the SVG (the headless-browser test checks the same with real text widths)."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

import pytest

from reports import svg

NS = {"s": "http://www.w3.org/2000/svg"}

ARMS = [f"arm{i} [level_{i}] · gpt-4o" for i in range(12)]
SPLITS = ["robotouille/synchronous", "robotouille/asynchronous", "alfworld/valid_unseen"]


def _box(el: ET.Element) -> tuple[float, float, float, float]:
    x, y, w, h = (float(el.get(k)) for k in ("x", "y", "width", "height"))
    return x, y, x + w, y + h


def _overlap(a, b) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def _many_arms_chart() -> ET.Element:
    values = {(s, a): (0.0 if i % 4 == 0 else 7.5 * i) for s in SPLITS for i, a in enumerate(ARMS)}
    errors = {k: (max(0.0, v - 10), min(100.0, v + 12)) for k, v in values.items()}
    text = svg.grouped_bars(
        "Success", SPLITS, ARMS, values, errors=errors, y_label="success (%)", y_max=100, value_fmt=lambda v: f"{v:.1f}"
    )
    return ET.fromstring(text)


def test_legend_of_twelve_arms_covers_no_bar():
    root = _many_arms_chart()
    bars = [_box(r) for r in root.iterfind(".//s:rect[@class]", NS) if r.get("class").split()[0] == "bar"]
    assert len(bars) == 36
    (legend,) = root.findall("s:g[@class='legend']", NS)
    box = _box(legend.find("s:rect[@class='legend-box']", NS))
    assert not [b for b in bars if _overlap(b, box)]
    # every key and every label (at the layout's width per character) lies inside the legend box,
    # and no two entries overlap (the browser test measures the real text)
    keys = [_box(k) for k in legend.iterfind("s:rect[@class='legend-key']", NS)]
    labels = [
        (float(t.get("x")), float(t.get("y")) - 11, float(t.get("x")) + svg.LEGEND_CHAR * len(t.text), float(t.get("y")) + 3)
        for t in legend.iterfind("s:text", NS)
    ]
    assert [t.text for t in legend.iterfind("s:text", NS)] == ARMS
    for item in keys + labels:
        assert box[0] <= item[0] and item[2] <= box[2] and box[1] <= item[1] and item[3] <= box[3], item
    entries = [(k[0], k[1], t[2], t[3]) for k, t in zip(keys, labels)]
    assert not [(a, b) for i, a in enumerate(entries) for b in entries[i + 1 :] if _overlap(a, b)]
    # the legend sits below the plot: below every bar and every category label, inside the chart
    assert box[1] > max(b[3] for b in bars)
    height = float(root.get("height"))
    assert root.get("viewBox") == f"0 0 {svg.WIDTH} {height:.0f}"
    assert box[3] <= height
    # twelve arms do not fit on one row: the chart is taller than a chart with two arms
    rows = len({y for y in (float(k[1]) for k in keys)})
    assert rows >= 3
    two = ET.fromstring(svg.grouped_bars("Success", SPLITS, ARMS[:2], {(SPLITS[0], ARMS[0]): 10.0}))
    assert height - float(two.get("height")) == pytest.approx((rows - 1) * svg.LEGEND_ROW)


def test_a_zero_bar_is_a_visible_mark_with_its_label():
    text = svg.grouped_bars(
        "Success",
        ["t2"],
        ["react", "recap"],
        {("t2", "react"): 0.0, ("t2", "recap"): 50.0},
        errors={("t2", "react"): (0.0, 79.3), ("t2", "recap"): (9.5, 90.5)},
        y_max=100,
        value_fmt=lambda v: f"{v:.1f}",
    )
    root = ET.fromstring(text)
    zero = root.find(".//s:rect[@class='bar zero']", NS)
    assert zero is not None and zero.get("fill") == svg.color(0)
    x0, y0, x1, y1 = _box(zero)
    assert y1 - y0 == svg.MIN_BAR and x1 - x0 > 1
    assert zero.find("s:title", NS).text == "t2 / react: 0.0 [0.0, 79.3]"
    labels = {t.text: t.get("transform") for t in root.iterfind(".//s:text[@class='value']", NS)}
    assert set(labels) == {"0.0", "50.0"}
    # the 0 label stands above its whisker (79.3 %), over the bar's centre
    tx, ty = (float(v) for v in re.match(r"translate\(([\d.]+),([\d.]+)\)", labels["0.0"]).groups())
    assert x0 <= tx - 3 <= x1
    whisker_top = min(
        float(ln.get("y2"))
        for ln in root.iterfind(".//s:line", NS)
        if ln.get("x1") == ln.get("x2") and abs(float(ln.get("x1")) - (tx - 3)) < 0.11
    )
    assert ty == pytest.approx(whisker_top - 3, abs=0.11)
    # a missing value (arm not run) draws nothing: no bar, no label
    root2 = ET.fromstring(svg.grouped_bars("S", ["t2"], ["react", "recap"], {("t2", "recap"): 50.0}))
    assert len(root2.findall(".//s:rect[@class='bar']", NS)) == 1
    assert [t.text for t in root2.iterfind(".//s:text[@class='value']", NS)] == ["50"]


def test_twenty_arms_get_twenty_colours():
    assert len({svg.color(i) for i in range(20)}) == 20
    assert svg.color(1) == "#f28e2b"  # the first ten stay Tableau 10 (the browser test looks for this orange)


def test_other_charts_put_their_legend_below_too():
    for text in (
        svg.stacked_shares("Modes", ["a", "b"], ["success", "step_cap"], {("a", "success"): 3, ("b", "step_cap"): 2}),
        svg.lines("Tokens", {"react": [(0, 1.0), (1, 3.0)], "recap": [(0, 2.0), (2, 5.0)]}),
    ):
        root = ET.fromstring(text)
        box = _box(root.find(".//s:rect[@class='legend-box']", NS))
        marks = [_box(r) for r in root.iterfind(".//s:rect[@class='bar']", NS)]
        marks += [
            (float(c.get("cx")), float(c.get("cy")), float(c.get("cx")), float(c.get("cy")))
            for c in root.iterfind(".//s:circle", NS)
        ]
        assert marks and box[1] > max(m[3] for m in marks)
        assert box[3] <= float(root.get("height"))
