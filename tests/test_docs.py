"""The documentation is true as written: README.md and the pages in docs/.

- The site builds with ``mkdocs build --strict`` (no broken link or anchor, no docstring the API
  reference cannot render); README.md stays a landing page; CITATION.cff, the TOML spec example
  and the module list are checked against what they describe.
- Every ``tdct solve`` output quoted in the docs matches a fresh solve of the same inputs.
- Every Python block runs, each on its own (a reader copies one block) in a fresh namespace in a
  scratch folder, so files it writes land there. A block preceded by the line ``<!-- slow -->`` is
  marked ``slow`` (``-m "not slow"`` skips it); CI runs them all. Where a ```text block follows a
  Python block (with at most one line of prose between), the block must print exactly that.
- Then notebooks/tour.ipynb runs top to bottom in a fresh kernel. It repeats the blocks' examples,
  so it runs after them in this file (one worker, ``--dist loadfile``) and loads their compiled
  programs from the session's cache.
"""

import ast
import contextlib
import io
import os
import re
import shlex
import subprocess
import sys
import tomllib
from pathlib import Path

import nbclient
import nbformat
import numpy as np
import pytest
import yaml

import tdct_jax as tdct
from tdct_jax import cli
from tdct_jax.spec import read_spec

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").rglob("*.md"))]
FENCE = re.compile(
    r"(?P<mark><!-- slow -->\n)?```python\n(?P<code>.*?)```\n"
    r"(?:\n*(?:[^\n`][^\n]*\n\n)?```text\n(?P<out>.*?)```)?",
    re.DOTALL,
)
README_MAX_LINES = 150


def name(path: Path) -> str:
    return str(path.relative_to(ROOT))


# --- the site and the landing page ----------------------------------------------------------------


def test_docs_site_builds_strict(tmp_path):
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    run = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-4000:]
    cli_page = (tmp_path / "site" / "cli" / "index.html").read_text()
    for verb in ("solve", "compliance", "ik", "simulate", "sweep", "synth", "calibrate", "reproduce"):
        assert f"usage: tdct {verb}" in cli_page, f"the CLI reference lacks tdct {verb} --help"


def test_readme_is_a_landing_page():
    text = README.read_text()
    assert len(text.splitlines()) < README_MAX_LINES
    # CI runs exactly the README's test command
    ci_command = (ROOT / ".ci" / "run").read_text().strip().splitlines()[-1]
    assert f"    {ci_command}\n" in text
    assert "    python -m pip install -e . && tdct reproduce --out tdct-reproduce\n" in text
    for target in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", text):
        assert (ROOT / target).exists(), f"README.md links to {target}, which does not exist"
    assert "## How to cite" in text and "Kinematics and Stiffness Modeling of Soft Robot" in text


def test_citation_file():
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0" and cff["type"] == "software" and cff["license"] == "MIT"
    assert cff["version"] == tdct.__version__
    (paper,) = cff["references"]
    assert paper["title"] == "Kinematics and Stiffness Modeling of Soft Robot With a Concentric Backbone"
    assert [a["family-names"] for a in paper["authors"]] == ["Xiao", "Musa", "Godage", "Su", "Chen"]
    assert "MIT License" in (ROOT / "LICENSE").read_text()


def test_sweep_spec_example_is_a_valid_spec(tmp_path):
    text = (ROOT / "docs" / "guide" / "sweeps.md").read_text()
    (spec,) = re.findall(r"```toml\n(.*?)```", text, re.DOTALL)
    tomllib.loads(spec)
    path = tmp_path / "grid.toml"
    path.write_text(spec)
    arguments = read_spec(path)
    assert [len(v) for v in arguments["grid"].values()] == [50, 50, 50, 50]


# --- quoted command output ------------------------------------------------------------------------

SOLVE_OUTPUT = re.compile(
    r"^\$ tdct solve (?P<flags>[^\n]*)\n"
    r"tip position \[mm\]: x = (?P<x>\S+), y = (?P<y>\S+), z = (?P<z>\S+)\n"
    r"tip angle \[deg\]: +(?P<angle>\S+)\n",
    re.MULTILINE,
)


def quoted_solves():
    for path in PAGES:
        for m in SOLVE_OUTPUT.finditer(path.read_text()):
            yield pytest.param(m, id=f"{name(path)}:{path.read_text().count(chr(10), 0, m.start()) + 1}")


def test_shape_picture_numbers_are_quoted():
    assert any("--plot docs/shape.png" in p.values[0]["flags"] for p in quoted_solves())


@pytest.mark.parametrize("quote", list(quoted_solves()))
def test_quoted_solve_output_matches_a_fresh_solve(quote):
    """The numbers quoted beside a ``tdct solve`` command (docs/shape.png's and docs/contact.png's
    among them) are what solving those inputs gives now, to the three decimals printed."""
    args = cli._parser().parse_args(["solve", *shlex.split(quote["flags"])])
    plain = not args.set and not args.no_gravity and args.tip_force is None and not any(args.tip_moment)
    plain = plain and not (args.displacements_mm or args.insertions_mm or args.point_load)
    assert plain, f"extend this test to the flags in {quote['flags']!r}"
    robot = tdct.Robot.paper() if args.robot is None else tdct.Robot.from_toml(ROOT / args.robot)
    act = tdct.Actuation(args.tensions or (0.0,) * robot.n_tendons, () if args.insertion_mm is None else args.insertion_mm * 1e-3)
    load = tdct.Loads.from_mass((args.tip_mass_g or 0.0) * 1e-3)
    scene = None if args.scene is None else tdct.read_scene(ROOT / args.scene)
    sol = tdct.solve(robot, act, load, scene=scene, solver=tdct.SolverOptions(steps=args.steps, max_iter=args.max_iter))
    quoted = np.array([float(quote[k]) for k in ("x", "y", "z", "angle")])
    fresh = np.array([*(1e3 * np.asarray(sol.tip_position)), np.degrees(float(sol.tip_angle))])
    assert np.all(np.abs(fresh - quoted) <= 5e-4 + 1e-9), f"quoted {quoted}, a fresh solve gives {fresh.round(3)}"


# --- Python blocks, then the notebook -------------------------------------------------------------


def blocks():
    for path in PAGES:
        text = path.read_text()
        for m in FENCE.finditer(text):
            line = text.count("\n", 0, m.start("code")) + 1
            marks = [pytest.mark.slow] if m.group("mark") else []
            yield pytest.param(path, m.group("code"), m.group("out"), id=f"{name(path)}:{line}", marks=marks)


def test_docs_have_python_blocks():
    found = list(blocks())
    assert len(found) >= 10
    assert any(p.values[0] == README for p in found), "the README's quickstart is not a ```python block"
    assert any(p.values[0] == README and p.values[2] for p in found), "the README's quickstart output is not quoted"


@pytest.mark.parametrize(("path", "code", "expected"), list(blocks()))
def test_python_block_runs_as_written(path, code, expected, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    bare = [n.lineno for n in ast.walk(ast.parse(code)) if isinstance(n, ast.Expr) and not isinstance(n.value, ast.Call)]
    assert not bare, f"bare expressions (lines {bare} of the block) show nothing when run: print or assert them"
    out = io.StringIO()
    with contextlib.redirect_stdout(out) if expected is not None else contextlib.nullcontext():
        exec(compile(code, name(path), "exec"), {"__name__": "docs"})
    if expected is not None:
        assert out.getvalue().strip() == expected.strip()


@pytest.mark.slow
def test_tour_notebook_runs(monkeypatch):
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    nb = nbformat.read(ROOT / "notebooks" / "tour.ipynb", as_version=4)
    nbclient.NotebookClient(
        nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(ROOT / "notebooks")}}
    ).execute()
    images = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs if "image/png" in o.get("data", {})]
    assert len(images) >= 7, f"expected a figure from each plotting cell, got {len(images)}"
