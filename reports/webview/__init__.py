"""``recap view``: a local web viewer over every episode of one or more run folders.

Stack, and why: Python's own ``http.server`` (``ThreadingHTTPServer``) serving server-rendered
HTML, one small stylesheet and one small vanilla script shipped with the package
(``reports/webview/static/``). No framework, no build step, no CDN and no new dependency: the
viewer is a handful of read-only GET pages on loopback for one user, which the standard library
serves well, and everything it shows comes from the report's own read-only DuckDB views
(:mod:`reports.views`, ``reports/sql/``) so the viewer and the report never disagree. A
framework (Flask, FastAPI, aiohttp's web server) would add a dependency and its release cycle
for routing we do in a dictionary; a JavaScript front end would need a bundler or a CDN.

Modules: :mod:`~reports.webview.snapshot`, :mod:`~reports.webview.search` and
:mod:`~reports.webview.catalog` (snapshots of the run folders, refreshed in the background),
:mod:`~reports.webview.listquery` (the list's URL parameters), :mod:`~reports.webview.runs`,
:mod:`~reports.webview.episodes` and :mod:`~reports.webview.compare` (the pages' queries), all
re-exported by :mod:`~reports.webview.data`; :mod:`~reports.webview.pages` (the HTML),
:mod:`~reports.webview.server` (HTTP, safety rules); the ``recap view`` command line is
:mod:`pipeline.cli.view`, its default port :data:`reports.ports.VIEWER_PORT`.
"""
