"""The HTML report: one self-contained page with inline CSS, SVG plots, the episode viewer and a little JavaScript.

Nothing is fetched (no network, no external files), so a report can be mailed or archived as is.

The page records script errors in ``<body data-js-errors>`` and sets ``data-report-ready`` when
its script has run, with what it measured of the laid-out plots (``data-plots-rendered``,
``data-legend-overlaps``, ``data-zero-bars-visible``); the headless-browser test reads them.
"""

from __future__ import annotations

from html import escape

from reports.model import Report, Section, Table, format_value
from reports.ports import VIEWER_PORT
from reports.viewer import anchor

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:0;color:#222;background:#fafafa}
main{max-width:1200px;margin:0 auto;padding:1rem 1.5rem 4rem}
h1{font-size:1.6rem}h2{border-bottom:2px solid #4e79a7;padding-bottom:.2rem;margin-top:2.5rem}
details.folded>summary{cursor:pointer}details.folded>summary h2{display:inline-block;margin-right:.5rem}
h3{margin-top:1.6rem}nav ul{display:flex;flex-wrap:wrap;gap:.4rem 1.2rem;list-style:none;padding:0}
.intro,.note{color:#555;font-size:.9rem;max-width:70rem}
.scroll{overflow-x:auto}
table.data{border-collapse:collapse;font-size:.82rem;margin:.4rem 0 1rem;background:#fff}
table.data th,table.data td{border:1px solid #ddd;padding:.25rem .45rem;text-align:left;vertical-align:top}
table.data th{background:#eef2f7}td.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
tr.invalid td{background:#fff4f4}
figure{margin:1rem 0;background:#fff;border:1px solid #e5e5e5;display:inline-block}
figcaption{font-size:.8rem;color:#555;padding:.2rem .5rem}
.warn{background:#fff3cd;border:1px solid #e0c36a;padding:.5rem .8rem}
.episode{background:#fff;border:1px solid #ddd;padding:.4rem 1rem;margin:1rem 0}
.badge{font-size:.75rem;padding:.1rem .4rem;border-radius:.3rem;color:#fff;vertical-align:middle}
.badge.ok{background:#59a14f}.badge.fail{background:#e15759}
dl.meta{display:flex;flex-wrap:wrap;gap:.2rem 1rem;font-size:.82rem}dl.meta dt{font-weight:600}dl.meta dd{margin:0}
ul.tree{list-style:none;padding-left:1.2rem;border-left:1px dotted #bbb}ul.tree.root{border-left:none;padding-left:0}
.node{margin:.3rem 0}.ntitle{font-weight:600}.ntag,.vtag,.mtag{color:#666;font-size:.78rem}
.node.failed>.ntitle{color:#c0392b}.node.open>.ntitle{color:#b8860b}
ol.versions{margin:.1rem 0 .2rem;padding-left:1.2rem;font-size:.85rem}
.think{font-style:italic;color:#333}ol.subtasks{margin:.1rem 0;padding-left:1.4rem}
pre{white-space:pre-wrap;word-break:break-word;margin:.1rem 0;font-size:.8rem}
ol.messages{list-style:none;padding:0}.msg{border-left:3px solid #4e79a7;padding-left:.5rem;margin:.4rem 0}
.msg.assistant{border-left-color:#f28e2b}.window-panel{border:2px solid #4e79a7;padding:.5rem;margin:.5rem 0;background:#f5f8fc}
button.show-window{font-size:.75rem;cursor:pointer}
"""

ERROR_HOOK = """
window.addEventListener('error', function (e) {
  var b = document.body || document.documentElement;
  var prev = b.getAttribute('data-js-errors') || '';
  b.setAttribute('data-js-errors', prev + (prev ? ' | ' : '') + (e.message || 'error'));
});
"""

SCRIPT = """
(function () {
  function expand(spec) {
    var out = [];
    spec.split(',').forEach(function (part) {
      if (!part) return;
      var ab = part.split('-');
      var a = parseInt(ab[0], 10), b = ab.length > 1 ? parseInt(ab[1], 10) : a;
      for (var i = a; i <= b; i++) out.push(i);
    });
    return out;
  }
  document.querySelectorAll('button.show-window').forEach(function (btn) {
    btn.addEventListener('click', function () {
      var id = btn.getAttribute('data-target');
      var panel = document.getElementById(id + '-window');
      var list = document.getElementById(id + '-messages');
      var seqs = expand(btn.getAttribute('data-seqs'));
      panel.innerHTML = '';
      var head = document.createElement('p');
      head.textContent = 'Window of call ' + btn.closest('tr').firstElementChild.textContent +
        ': ' + seqs.length + ' messages (' + btn.getAttribute('data-seqs') + ')' +
        (btn.getAttribute('data-response') ? '; reply stored as message ' + btn.getAttribute('data-response') : '');
      panel.appendChild(head);
      var ol = document.createElement('ol');
      ol.className = 'messages';
      seqs.forEach(function (s) {
        var li = list ? list.querySelector('li[data-seq="' + s + '"]') : null;
        if (li) { ol.appendChild(li.cloneNode(true)); }
        else { var miss = document.createElement('li'); miss.textContent = '#' + s + ' (not in the messages table)'; ol.appendChild(miss); }
      });
      panel.appendChild(ol);
      panel.hidden = false;
      panel.scrollIntoView({block: 'nearest'});
    });
  });
  // deep link: report.html#call-<episode anchor>-<call index> opens that call's window
  var m = /^#(call-.+)$/.exec(window.location.hash);
  if (m) {
    var target = document.getElementById(m[1]);
    if (target) {
      var d = target.closest('details');
      if (d) d.open = true;
      target.click();
    }
  }
  var rendered = 0, overlaps = 0, zeros = 0;
  function hit(a, b) { return a.left < b.right && b.left < a.right && a.top < b.bottom && b.top < a.bottom; }
  document.querySelectorAll('svg.chart').forEach(function (el) {
    var r = el.getBoundingClientRect();
    if (r.width > 0 && r.height > 0 && el.querySelectorAll('.bar, .line').length > 0) rendered++;
    // layout checks read by the browser test: legend entries (as laid out, real text widths)
    // that touch a bar or each other, and 0 bars that are painted at least 2px tall
    var bars = Array.prototype.map.call(el.querySelectorAll('.bar'), function (b) { return b.getBoundingClientRect(); });
    var entries = [];
    el.querySelectorAll('g.legend rect.legend-key').forEach(function (key) {
      var k = key.getBoundingClientRect(), t = key.nextElementSibling.getBoundingClientRect();
      entries.push({left: k.left, top: Math.min(k.top, t.top), right: t.right, bottom: Math.max(k.bottom, t.bottom)});
    });
    entries.forEach(function (e, i) {
      bars.forEach(function (b) { if (hit(e, b)) overlaps++; });
      entries.slice(i + 1).forEach(function (o) { if (hit(e, o)) overlaps++; });
    });
    el.querySelectorAll('.bar.zero').forEach(function (b) {
      var z = b.getBoundingClientRect();
      if (z.height >= 2 && z.width >= 1) zeros++;
    });
  });
  document.body.setAttribute('data-plots-rendered', String(rendered));
  document.body.setAttribute('data-legend-overlaps', String(overlaps));
  document.body.setAttribute('data-zero-bars-visible', String(zeros));
  document.body.setAttribute('data-report-ready', '1');
})();
"""


#: episode ids (``.ep-link``) point at ``recap view`` once a ping to it answers: the port on
#: ``<body data-viewer-port>`` (the viewer's default) or ``?viewer=PORT`` in the page's URL, or the
#: page's own origin when the viewer serves it (``/report``). An image ping, so a report opened
#: from a file needs no CORS; without a viewer the links stay as they are (static report).
VIEWER_LINKS = """
(function () {
  var links = document.querySelectorAll('.ep-link');
  if (!links.length) return;
  var m = /[?&]viewer=(\\d{1,5})(?:&|$)/.exec(window.location.search);
  var served = /^https?:$/.test(location.protocol) && location.pathname === '/report';
  var base = served ? location.origin + '/' : 'http://127.0.0.1:' + (m ? m[1] : document.body.getAttribute('data-viewer-port')) + '/';
  var img = new Image();
  img.onload = function () {
    links.forEach(function (el) {
      var run = el.getAttribute('data-run');
      var a = el.querySelector('a');
      if (!a) { a = document.createElement('a'); a.textContent = el.textContent; el.textContent = ''; el.appendChild(a); }
      a.href = base + 'episode?id=' + encodeURIComponent(el.getAttribute('data-episode')) + (run ? '&run=' + encodeURIComponent(run) : '');
    });
    document.body.setAttribute('data-viewer', base);
  };
  img.onerror = function () { document.body.setAttribute('data-viewer', 'none'); };
  img.src = base + 'ping.gif?t=' + Date.now();
})();
"""


def _episode_link(episode_id: str, in_viewer: bool) -> str:
    inner = f'<a href="#{anchor(episode_id)}">{escape(episode_id)}</a>' if in_viewer else escape(episode_id)
    return f'<span class="ep-link" data-episode="{escape(episode_id)}">{inner}</span>'


def _cell(kind: str, value: object, viewer: set[str], key: str = "", names: dict[str, str] | None = None) -> str:
    if key == "run_id" and names and str(value) in names:  # a run by its name, its id on hover
        return f'<span class="run" title="{escape(str(value))}">{escape(names[str(value)])}</span>'
    if kind == "list" and isinstance(value, list):
        # every episode id is a link: to the report's own viewer when the episode is in it, and to
        # `recap view` when one runs (VIEWER_LINKS); plain text otherwise
        return ", ".join(_episode_link(str(v), str(v) in viewer) for v in value)
    return escape(format_value(kind, value))


def table_html(t: Table, viewer: set[str], names: dict[str, str] | None = None) -> str:
    """One table as HTML: its title and note, then the table (tagged with its SQL source); episode ids in
    ``viewer`` link to the page's own viewer; a run id is shown as the run's name (``names``)."""
    head = "".join(f"<th>{escape(c.header)}</th>" for c in t.columns)
    body = []
    for row in t.rows:
        cells = "".join(
            f'<td class="{"num" if c.kind not in ("text", "list") else ""}">{_cell(c.kind, row.get(c.key), viewer, c.key, names)}</td>'
            for c in t.columns
        )
        body.append(f"<tr>{cells}</tr>")
    empty = f'<tr><td colspan="{len(t.columns)}">no rows</td></tr>' if not t.rows else ""
    note = f'<p class="note">{escape(t.note)}</p>' if t.note else ""
    return (
        f'<h3 id="t-{escape(t.name)}">{escape(t.title)}</h3>{note}'
        f'<div class="scroll"><table class="data" data-source="{escape(t.source)}.sql"><thead><tr>{head}</tr></thead>'
        f"<tbody>{''.join(body)}{empty}</tbody></table></div>"
    )


#: sections the HTML page opens with, in this order (issue 36 item 12: the results before a screen of metadata)
FIRST_SECTIONS = ("paper", "success")
#: sections the HTML page folds (closed ``<details>``): what the report covers, not what the runs found
FOLDED_SECTIONS = ("overview",)


def html_order(sections: list[Section]) -> list[Section]:
    """The sections as the HTML page shows them: :data:`FIRST_SECTIONS` first, then the others in the
    report's order (the text formats keep the report's order)."""
    first = [s for k in FIRST_SECTIONS for s in sections if s.key == k]
    return first + [s for s in sections if s not in first]


def render_html(report: Report) -> str:
    """The whole report as one self-contained HTML page (no external files or network): the paper's tables
    and the success rates first, the overview (what the report covers, the runs) folded after them."""
    viewer = set(report.viewer_episodes)
    ordered = html_order(list(report.sections))
    nav = "".join(f'<li><a href="#s-{s.key}">{escape(s.title)}</a></li>' for s in ordered)
    if report.viewer_html:
        nav += '<li><a href="#viewer">Episode viewer</a></li>'
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{escape(report.title)}</title><style>{CSS}</style><script>{ERROR_HOOK}</script></head>",
        f'<body data-viewer-port="{VIEWER_PORT}"><main>',
        f"<h1>{escape(report.title)}</h1>",
        '<p class="intro">Run folders: ' + ", ".join(f"<code>{escape(d)}</code>" for d in report.run_dirs) + "</p>",
    ]
    if report.skipped:
        parts.append(
            '<div class="warn"><strong>Unreadable part files were skipped:</strong><ul>'
            + "".join(f"<li><code>{escape(s.path)}</code>: {escape(s.error)}</li>" for s in report.skipped)
            + "</ul></div>"
        )
    parts.append(f"<nav><ul>{nav}</ul></nav>")
    for s in ordered:
        folded = s.key in FOLDED_SECTIONS
        parts.append(
            f'<section id="s-{s.key}">'
            + (
                f'<details class="folded"><summary><h2>{escape(s.title)}</h2></summary>'
                if folded
                else f"<h2>{escape(s.title)}</h2>"
            )
        )
        if s.intro:
            parts.append(f'<p class="intro">{escape(s.intro)}</p>')
        for p in s.plots:
            parts.append(
                f'<figure id="p-{escape(p.name)}" data-source="{escape(p.source)}.sql">{p.svg}<figcaption>{escape(p.title)}'
                f"{(' — ' + escape(p.note)) if p.note else ''}</figcaption></figure>"
            )
        for t in s.tables:
            parts.append(table_html(t, viewer, report.run_names))
        parts.append("</details></section>" if folded else "</section>")
    if report.viewer_html:
        parts.append(report.viewer_html)
    parts.append(f"</main><script>{SCRIPT}</script><script>{VIEWER_LINKS}</script></body></html>")
    return "\n".join(parts)
