"""MkDocs hook: the command-line reference shows each command's ``--help`` as the installed parser
prints it, so that page cannot fall behind the flags.

A line ``<!-- tdct-help VERB -->`` in a page becomes a text block with ``tdct VERB --help``;
``<!-- tdct-help -->`` with ``tdct --help``. The parser comes from this checkout's ``tdct_jax.cli``
(no JAX computation runs), at a fixed width of 100 columns.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import sys
from pathlib import Path

MARK = re.compile(r"^<!-- tdct-help(?: (?P<verb>[a-z]+))? -->$", re.MULTILINE)
ROOT = Path(__file__).resolve().parents[1]


def _help(verb: str | None) -> str:
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    from tdct_jax import cli

    os.environ["COLUMNS"] = "100"  # argparse wraps to the terminal's width
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
        cli._parser().parse_args([verb, "--help"] if verb else ["--help"])
    text = out.getvalue().strip()
    if not text.startswith("usage: tdct"):
        raise RuntimeError(f"tdct {verb or ''} --help printed no usage: {text[:200]!r}")
    return text


def on_page_markdown(markdown: str, **kwargs) -> str:
    return MARK.sub(lambda m: "```text\n" + _help(m.group("verb")) + "\n```", markdown)
