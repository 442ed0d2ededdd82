"""MkDocs hooks of this site (mkdocs.yml: ``hooks``); not a page.

- The command-line page (``cli.md``): each ``<!-- uavris-help: COMMAND -->`` becomes that
  command's ``--help`` as printed by the installed package, so the page cannot drift from it.
- The reports under ``results/`` (verbatim copies of a run's ``report.md``): their figures
  are ``figures/NAME`` of the run directory; where the repository keeps the quick run's
  (``docs/figures/quick_NAME``, for ``results/quick-report.md``) the link points there,
  otherwise the image becomes a line naming the figure, so the copy stays verbatim and the
  build strict.
- API pages: docstrings are prose with Sphinx roles (``:class:`X```); the role's prefix is
  dropped from the HTML, leaving the name as code.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
from pathlib import Path

DOCS = Path(__file__).resolve().parent
HELP_MARK = re.compile(r"^<!-- uavris-help: ([\w-]+) -->$", re.M)
REPORT_FIGURE = re.compile(r"!\[([^\]]*)\]\(figures/([^)]+)\)")
ROLE = re.compile(r":(?:class|func|meth|mod|attr|data|exc|obj|const):(?=<code>)")


def command_help(name: str) -> str:
    """``uavris NAME --help`` as the package prints it, 100 columns, no colours or boxes."""
    from uavris.cli import COMMANDS, command

    if name not in COMMANDS:
        raise ValueError(f"cli.md asks for the help of {name!r}, which is not a uavris command ({', '.join(COMMANDS)})")
    os.environ["COLUMNS"] = "100"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
        try:
            command(name)(["--help"])
        except SystemExit as e:
            if e.code not in (0, None):
                raise RuntimeError(f"uavris {name} --help exited with {e.code}:\n{buf.getvalue()}") from None
    text = "\n".join(line.rstrip() for line in buf.getvalue().splitlines()).strip("\n")
    if not text.startswith(f"usage: uavris {name}"):
        raise RuntimeError(f"uavris {name} --help printed no usage:\n{text}")
    return text


def _report_figure(match: re.Match, kept: bool) -> str:
    alt, name = match.group(1), match.group(2)
    if kept and (DOCS / "figures" / f"quick_{name}").is_file():
        return f"![{alt}](../figures/quick_{name})"
    return f"*({alt}: `figures/{name}` of the run directory, not kept in the repository.)*"


def on_page_markdown(markdown: str, page, config, files) -> str:
    src = page.file.src_uri
    if src == "cli.md":
        return HELP_MARK.sub(lambda m: f"```text\n{command_help(m.group(1))}\n```", markdown)
    if src.startswith("results/"):
        return REPORT_FIGURE.sub(lambda m: _report_figure(m, src == "results/quick-report.md"), markdown)
    return markdown


def on_page_content(html: str, page, config, files) -> str:
    if page.file.src_uri.startswith("api/"):
        return ROLE.sub("", html).replace("<code>~", "<code>")
    return html
