"""The report's SVG charts, written by hand: grouped bars with error whiskers, stacked share bars, line charts.

Inline SVG keeps the HTML report self-contained (no plotting library, no network) and every mark
carries a ``<title>`` so hovering shows the exact value.

The legend sits below the plot area in as many rows as it needs (the chart grows taller), so it
never covers a bar however many arms a sweep has; a bar of 0 is drawn as a thin mark on the axis
with its value label, so "0 %" reads differently from "not run" (no bar, no label).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from html import escape

#: Tableau 10 (distinguishable, colour-blind friendly enough for a handful of series), then the
#: other colours of Tableau 20, so that up to 20 arms get a colour each
PALETTE = (
    "#4e79a7",
    "#f28e2b",
    "#e15759",
    "#76b7b2",
    "#59a14f",
    "#edc948",
    "#b07aa1",
    "#ff9da7",
    "#9c755f",
    "#bab0ac",
    "#a0cbe8",
    "#ffbe7d",
    "#8cd17d",
    "#b6992d",
    "#499894",
    "#86bcb6",
    "#ff9d9a",
    "#79706e",
    "#d37295",
    "#d4a6c8",
)

WIDTH = 760
#: height of the chart without its legend (the legend's rows are added below)
HEIGHT = 330
#: a bar is at least this tall (pixels), so a value of 0 stays visible on the axis
MIN_BAR = 3.0
#: legend layout: left edge, row height, key size, width per character (11px font, generous)
LEGEND_X = 60.0
LEGEND_ROW = 16.0
LEGEND_CHAR = 6.6
FONT = "font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif"


def color(i: int) -> str:
    """The palette colour of series ``i``; wraps around after the palette's last colour."""
    return PALETTE[i % len(PALETTE)]


def nice_ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    """About ``n`` round tick values covering [lo, hi]."""
    if hi <= lo:
        hi = lo + 1.0
    raw = (hi - lo) / max(n, 1)
    mag = 10 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw)
    start = math.floor(lo / step) * step
    ticks = []
    t = start
    while t <= hi + step * 1e-9:
        ticks.append(round(t, 10))
        t += step
    if ticks[-1] < hi:
        ticks.append(round(ticks[-1] + step, 10))
    return ticks


def _fmt_tick(v: float) -> str:
    if abs(v) >= 1000:
        return f"{v:,.0f}"
    if v == int(v):
        return str(int(v))
    return f"{v:g}"


def legend_items(names: Sequence[str]) -> list[tuple[float, int]]:
    """(x, row) of each legend entry: left to right, wrapping at the chart's right edge."""
    out = []
    x, row = LEGEND_X, 0
    for name in names:
        w = 14 + LEGEND_CHAR * len(name)
        if x > LEGEND_X and x + w > WIDTH - 10:
            x, row = LEGEND_X, row + 1
        out.append((x, row))
        x += w + 12
    return out


def _legend(names: Sequence[str], top: float) -> tuple[list[str], float]:
    """The legend as one ``<g class="legend">`` below the plot, from ``top``; returns its parts
    and the height it takes. A ``legend-box`` rectangle covers every entry."""
    if not names:
        return [], 0.0
    items = legend_items(names)
    rows = items[-1][1] + 1
    right = max(x + 14 + LEGEND_CHAR * len(n) for (x, _), n in zip(items, names))
    height = rows * LEGEND_ROW + 8
    parts = [
        '<g class="legend">',
        f'<rect class="legend-box" x="{LEGEND_X - 6:.1f}" y="{top:.1f}" width="{right - LEGEND_X + 12:.1f}" '
        f'height="{height:.1f}" fill="#ffffff" stroke="#e5e5e5"/>',
    ]
    for i, ((x, row), name) in enumerate(zip(items, names)):
        y = top + 4 + row * LEGEND_ROW
        parts.append(f'<rect class="legend-key" x="{x:.1f}" y="{y + 2:.1f}" width="10" height="10" fill="{color(i)}"/>')
        parts.append(f'<text x="{x + 14:.1f}" y="{y + 11:.1f}">{escape(name)}</text>')
    parts.append("</g>")
    return parts, height


def _frame(title: str, body: list[str], legend: Sequence[str], height: int = HEIGHT) -> str:
    """The chart: title, plot body (laid out within ``height``), then the legend below it."""
    legend_parts, legend_h = _legend(legend, height + 6)
    total = height + (legend_h + 12 if legend_parts else 0)
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" class="chart" viewBox="0 0 {WIDTH} {total:.0f}" '
        f'width="{WIDTH}" height="{total:.0f}" role="img" aria-label="{escape(title)}" style="{FONT};font-size:11px">',
        f"<title>{escape(title)}</title>",
        f'<rect x="0" y="0" width="{WIDTH}" height="{total:.0f}" fill="#ffffff"/>',
        f'<text x="{WIDTH / 2}" y="16" text-anchor="middle" font-size="13" font-weight="600">{escape(title)}</text>',
    ]
    parts.extend(body)
    parts.extend(legend_parts)
    parts.append("</svg>")
    return "\n".join(parts)


def _y_axis(
    ticks: list[float], y_of: Callable[[float], float], left: float, right: float, label: str, fmt: Callable[[float], str]
) -> list[str]:
    out = []
    for t in ticks:
        y = y_of(t)
        out.append(f'<line x1="{left}" x2="{right}" y1="{y:.1f}" y2="{y:.1f}" stroke="#e5e5e5"/>')
        out.append(f'<text x="{left - 6}" y="{y + 4:.1f}" text-anchor="end">{escape(fmt(t))}</text>')
    mid = (y_of(ticks[0]) + y_of(ticks[-1])) / 2
    out.append(f'<text transform="translate(14,{mid:.1f}) rotate(-90)" text-anchor="middle">{escape(label)}</text>')
    return out


def _category_label(cat: str, x: float, bottom: float, slot: float, n_cat: int) -> str:
    """Horizontal labels broken at '/' and ' · ' while they fit; rotated and cut otherwise."""
    lines = [p for part in cat.replace(" (", " · (").split(" · ") for p in _split_slash(part)]
    max_chars = int(slot / 6.5)
    if n_cat <= 8 and len(lines) <= 4 and all(len(li) <= max_chars for li in lines):
        spans = "".join(f'<tspan x="{x:.1f}" dy="{0 if i == 0 else 12}">{escape(li)}</tspan>' for i, li in enumerate(lines))
        return f'<text x="{x:.1f}" y="{bottom + 15}" text-anchor="middle">{spans}</text>'
    label = cat if len(cat) <= 24 else cat[:23] + "…"
    return f'<text transform="translate({x:.1f},{bottom + 12}) rotate(-25)" text-anchor="end">{escape(label)}</text>'


def _split_slash(text: str) -> list[str]:
    head, sep, tail = text.partition("/")
    return [head + sep, tail] if sep and tail else [text]


def grouped_bars(
    title: str,
    categories: Sequence[str],
    series: Sequence[str],
    values: Mapping[tuple[str, str], float],
    *,
    errors: Mapping[tuple[str, str], tuple[float, float]] | None = None,
    y_label: str = "",
    y_max: float | None = None,
    value_fmt: Callable[[float], str] = _fmt_tick,
) -> str:
    """Bars per category, one per series; ``errors`` draws [lo, hi] whiskers. Every bar carries its
    value as a label above it (above its whisker), and is at least MIN_BAR tall, so a 0 shows."""
    left, right, top, bottom = 60.0, WIDTH - 10.0, 60.0, HEIGHT - 70.0  # room above for value labels
    vals = [v for v in values.values() if v is not None]
    hi = max(vals + [hi for (_, hi) in (errors or {}).values()] + [0.0])
    ticks = nice_ticks(0.0, y_max if y_max is not None else (hi or 1.0))
    y_top = ticks[-1]

    def y_of(v: float) -> float:
        return bottom - (bottom - top) * (v / y_top if y_top else 0.0)

    body = _y_axis(ticks, y_of, left, right, y_label, _fmt_tick)
    n_cat = max(len(categories), 1)
    slot = (right - left) / n_cat
    bar_w = max(2.0, min(40.0, slot * 0.8 / max(len(series), 1)))
    for ci, cat in enumerate(categories):
        x0 = left + ci * slot + (slot - bar_w * len(series)) / 2
        for si, s in enumerate(series):
            v = values.get((cat, s))
            if v is None:
                continue
            x = x0 + si * bar_w
            y = min(y_of(v), bottom - MIN_BAR)
            tip = f"{cat} / {s}: {value_fmt(v)}"
            err = (errors or {}).get((cat, s))
            if err is not None:
                tip += f" [{value_fmt(err[0])}, {value_fmt(err[1])}]"
            body.append(
                f'<rect class="bar{" zero" if v == 0 else ""}" x="{x:.1f}" y="{y:.1f}" width="{bar_w - 1:.1f}" '
                f'height="{bottom - y:.1f}" fill="{color(si)}"><title>{escape(tip)}</title></rect>'
            )
            cx = x + (bar_w - 1) / 2
            label_y = y
            if err is not None:
                y1, y2 = y_of(err[0]), y_of(err[1])
                body.append(f'<line x1="{cx:.1f}" x2="{cx:.1f}" y1="{y1:.1f}" y2="{y2:.1f}" stroke="#333"/>')
                for yy in (y1, y2):
                    body.append(f'<line x1="{cx - 3:.1f}" x2="{cx + 3:.1f}" y1="{yy:.1f}" y2="{yy:.1f}" stroke="#333"/>')
                label_y = min(label_y, y1, y2)
            # vertical, so that narrow bars of many arms keep their labels apart
            body.append(
                f'<text class="value" transform="translate({cx + 3:.1f},{label_y - 3:.1f}) rotate(-90)" '
                f'font-size="9" fill="#333">{escape(value_fmt(v))}</text>'
            )
        body.append(_category_label(cat, left + ci * slot + slot / 2, bottom, slot, n_cat))
    body.append(f'<line x1="{left}" x2="{right}" y1="{bottom}" y2="{bottom}" stroke="#333"/>')
    return _frame(title, body, series)


def stacked_shares(
    title: str,
    categories: Sequence[str],
    layers: Sequence[str],
    counts: Mapping[tuple[str, str], float],
    *,
    y_label: str = "share of episodes (%)",
) -> str:
    """One bar per category split into layers by their share of the category's total."""
    left, right, top, bottom = 60.0, WIDTH - 10.0, 36.0, HEIGHT - 70.0

    def y_of(v: float) -> float:
        return bottom - (bottom - top) * v / 100.0

    body = _y_axis([0, 25, 50, 75, 100], y_of, left, right, y_label, _fmt_tick)
    slot = (right - left) / max(len(categories), 1)
    bar_w = min(60.0, slot * 0.7)
    for ci, cat in enumerate(categories):
        total = sum(counts.get((cat, layer), 0) for layer in layers)
        x = left + ci * slot + (slot - bar_w) / 2
        acc = 0.0
        for li, layer in enumerate(layers):
            c = counts.get((cat, layer), 0)
            if not c or not total:
                continue
            share = 100.0 * c / total
            y1, y2 = y_of(acc + share), y_of(acc)
            body.append(
                f'<rect class="bar" x="{x:.1f}" y="{y1:.1f}" width="{bar_w:.1f}" height="{y2 - y1:.1f}" fill="{color(li)}">'
                f"<title>{escape(f'{cat}: {layer} {c:g} of {total:g} ({share:.1f}%)')}</title></rect>"
            )
            acc += share
        body.append(_category_label(cat, x + bar_w / 2, bottom, slot, len(categories)))
    body.append(f'<line x1="{left}" x2="{right}" y1="{bottom}" y2="{bottom}" stroke="#333"/>')
    return _frame(title, body, layers)


#: the plotting area of an x-y plot (lines, scatter): left, right, top, bottom
_XY_AREA = (70.0, WIDTH - 10.0, 36.0, HEIGHT - 45.0)


def _xy_axes(
    x_ticks: list[float], y_ticks: list[float], x_label: str, y_label: str, y_fmt: Callable[[float], str]
) -> tuple[Callable[[float], float], Callable[[float], float], list[str]]:
    """The x and y scales of an x-y plot over its ticks (x from its first tick, y from 0) and the
    axes drawn: the y grid, tick labels and label, the x tick labels and label."""
    left, right, top, bottom = _XY_AREA

    def x_of(v: float) -> float:
        span = (x_ticks[-1] - x_ticks[0]) or 1.0
        return left + (right - left) * (v - x_ticks[0]) / span

    def y_of(v: float) -> float:
        return bottom - (bottom - top) * v / (y_ticks[-1] or 1.0)

    body = _y_axis(y_ticks, y_of, left, right, y_label, y_fmt)
    for t in x_ticks:
        body.append(f'<text x="{x_of(t):.1f}" y="{bottom + 14}" text-anchor="middle">{escape(_fmt_tick(t))}</text>')
    body.append(f'<text x="{(left + right) / 2}" y="{HEIGHT - 8}" text-anchor="middle">{escape(x_label)}</text>')
    return x_of, y_of, body


def lines(
    title: str,
    series: Mapping[str, Sequence[tuple[float, float]]],
    *,
    x_label: str = "",
    y_label: str = "",
) -> str:
    """One polyline per series (points sorted by x), with dots when there are few points."""
    left, right, _top, bottom = _XY_AREA
    xs = [x for pts in series.values() for x, _ in pts]
    ys = [y for pts in series.values() for _, y in pts]
    x_ticks = nice_ticks(min(xs, default=0.0), max(xs, default=1.0), 8)
    x_of, y_of, body = _xy_axes(x_ticks, nice_ticks(0.0, max(ys, default=1.0) or 1.0), x_label, y_label, _fmt_tick)
    for si, (name, pts) in enumerate(series.items()):
        pts = sorted(pts)
        if not pts:
            continue
        path = " ".join(f"{x_of(x):.1f},{y_of(y):.1f}" for x, y in pts)
        body.append(
            f'<polyline class="line" fill="none" stroke="{color(si)}" stroke-width="2" points="{path}"><title>{escape(name)}</title></polyline>'
        )
        if len(pts) <= 60:
            for x, y in pts:
                body.append(
                    f'<circle cx="{x_of(x):.1f}" cy="{y_of(y):.1f}" r="2.5" fill="{color(si)}">'
                    f"<title>{escape(f'{name}: {_fmt_tick(x)} → {y:,.1f}')}</title></circle>"
                )
    body.append(f'<line x1="{left}" x2="{right}" y1="{bottom}" y2="{bottom}" stroke="#333"/>')
    return _frame(title, body, list(series))


def scatter(
    title: str,
    series: Mapping[str, Sequence[tuple[float, float, bool]]],
    *,
    x_label: str = "",
    y_label: str = "",
    y_fmt: Callable[[float], str] = _fmt_tick,
) -> str:
    """One dot per point ``(x, y, filled)``, a colour per series; a filled dot is a success, a ring a
    failure. Every dot carries its values as ``data-x`` / ``data-y`` (and ``data-series``,
    ``data-filled``) and a ``<title>``, so a reader (or a test) gets the numbers back exactly."""
    left, right, _top, bottom = _XY_AREA
    xs = [p[0] for pts in series.values() for p in pts]
    ys = [p[1] for pts in series.values() for p in pts]
    x_ticks = nice_ticks(0.0, max(xs, default=1.0) or 1.0, 8)
    x_of, y_of, body = _xy_axes(x_ticks, nice_ticks(0.0, max(ys, default=1.0) or 1.0), x_label, y_label, y_fmt)
    for si, (name, pts) in enumerate(series.items()):
        for x, y, filled in sorted(pts):
            fill = color(si) if filled else "none"
            tip = f"{name}: {_fmt_tick(x)}, {y_fmt(y)} ({'resolved' if filled else 'not resolved'})"
            body.append(
                f'<circle class="dot" data-series="{escape(name)}" data-x="{x:g}" data-y="{y:g}" '
                f'data-filled="{str(filled).lower()}" cx="{x_of(x):.1f}" cy="{y_of(y):.1f}" r="3" fill="{fill}" '
                f'stroke="{color(si)}"><title>{escape(tip)}</title></circle>'
            )
    body.append(f'<line x1="{left}" x2="{right}" y1="{bottom}" y2="{bottom}" stroke="#333"/>')
    return _frame(title, body, list(series))
