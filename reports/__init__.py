"""Reports over run folders: every number is a DuckDB query kept in ``reports/sql/``.

* :func:`reports.views.open_runs` - a read-only DuckDB connection with one view per table over
  the readable part files of one or more runs, plus named views (``terminal``, ``calls``,
  ``failures``, ...);
* :func:`reports.commands.report_main` / :func:`reports.commands.sql_main` - ``recap report``
  (Markdown, self-contained HTML with plots and an episode viewer, LaTeX, CSV) and ``recap sql``.
"""
