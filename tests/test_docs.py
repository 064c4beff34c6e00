"""The documentation runs as written: every Python block in README.md, each on its own (a reader
copies one block), then notebooks/tour.ipynb top to bottom in a fresh kernel.

A README block preceded by the line ``<!-- slow -->`` is marked ``slow`` (``-m "not slow"`` skips
it); CI runs them all. Each block runs in a fresh namespace in a scratch folder, so files it writes
land there. The notebook repeats the README's examples, so it runs after them in this file (one
worker, ``--dist loadfile``) and loads their compiled programs from the session's cache.
"""

import os
import re
from pathlib import Path

import nbclient
import nbformat
import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
FENCE = re.compile(r"(?P<mark><!-- slow -->\n)?```python\n(?P<code>.*?)```", re.DOTALL)


def blocks():
    text = README.read_text()
    for m in FENCE.finditer(text):
        line = text.count("\n", 0, m.start("code")) + 1
        marks = [pytest.mark.slow] if m.group("mark") else []
        yield pytest.param(m.group("code"), id=f"README.md:{line}", marks=marks)


def test_readme_has_python_blocks():
    assert len(list(blocks())) >= 5


@pytest.mark.parametrize("code", list(blocks()))
def test_readme_block_runs_as_written(code, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "README.md", "exec"), {"__name__": "readme"})


def test_tour_notebook_runs(monkeypatch):
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    nb = nbformat.read(ROOT / "notebooks" / "tour.ipynb", as_version=4)
    nbclient.NotebookClient(
        nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(ROOT / "notebooks")}}
    ).execute()
    images = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs if "image/png" in o.get("data", {})]
    assert len(images) >= 7, f"expected a figure from each plotting cell, got {len(images)}"
