"""The port ``recap view`` listens on by default: the HTML report looks for a running viewer there.

Its own module so the report (:mod:`reports.render_html`) and the viewer's command line read one
number without either importing the other.
"""

#: the port ``recap view`` listens on by default; the HTML report looks for a viewer there
VIEWER_PORT = 8765
