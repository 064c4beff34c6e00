"""Every Python block in README.md runs as written, each on its own (a reader copies one block).

A block preceded by the line ``<!-- slow -->`` is marked ``slow`` (``-m "not slow"`` skips it);
CI runs them all. Each block runs in a fresh namespace in a scratch folder, so files it writes
land there.
"""

import re
from pathlib import Path

import pytest

README = Path(__file__).parent.parent / "README.md"
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
