"""Reports over run folders: every number is a DuckDB query kept in ``reports/sql/``.

* :func:`reports.views.open_runs` - a read-only DuckDB connection with one view per table over
  the readable part files of one or more runs, plus named views (``terminal``, ``calls``,
  ``failures``, ...);
* :func:`reports.build.build_report` / :func:`reports.build.write_report` - what ``recap report``
  (:mod:`pipeline.cli.report`) writes: Markdown, self-contained HTML with plots and an episode
  viewer, LaTeX, CSV; ``recap sql`` is :mod:`pipeline.cli.sql`.
"""
