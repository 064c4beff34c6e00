"""tdct solve --scene (issue 26): the contacts in the text and JSON output are the API's, the tip
rests on the shipped table with no gap, the contact forces and the base load balance the weight;
a bad scene file exits 2 naming the obstacle and the field before any solve; --plot draws the
obstacles and the contact forces. One contact solve configuration (the paper's robot on the
shipped scene, the CLI's defaults) serves every solving test."""

import json
from types import SimpleNamespace

import matplotlib
import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax import cli, plotting
from tdct_jax.cli import main
from tdct_jax.description import section_area
from tdct_jax.inputs import STANDARD_GRAVITY
from tdct_jax.scene import SCENES

matplotlib.use("Agg")

TABLE = str(SCENES / "table.toml")
SOLVE = ["solve", "--tensions", "0,0,10,0", "--insertion-mm", "60", "--scene", TABLE]
TABLE_HEIGHT, RADIUS = -0.045, 0.01  # the shipped table's surface and the paper robot's radius [m]
GAP_ATOL = 1e-12  # m
BALANCE_ATOL = 1e-9  # N


@pytest.fixture(scope="module")
def on_the_table():
    """The API's solve of the inputs SOLVE types."""
    return tdct.solve(tdct.Robot.paper(), tdct.Actuation([0.0, 0.0, 10.0, 0.0], 0.06), scene=tdct.read_scene(TABLE))


def test_json_lists_the_contacts_and_the_wrench_on_each_obstacle(capsys, on_the_table):
    assert main([*SOLVE, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    sol, c = on_the_table, on_the_table.contact
    j, o = np.nonzero(np.asarray(c.active))
    assert [x["obstacle"] for x in out["contacts"]] == [("table", "ball")[i] for i in o]
    assert {x["obstacle"] for x in out["contacts"]} == {"table", "ball"}  # the ball under the body, the tip on the table
    np.testing.assert_allclose([x["s_mm"] for x in out["contacts"]], 1e3 * np.asarray(c.s)[j], rtol=1e-12)
    np.testing.assert_allclose([x["force_N"] for x in out["contacts"]], np.asarray(c.force)[j, o], rtol=1e-12)
    assert all(x["force_N"] > 0 for x in out["contacts"])
    # the tip rests on the table: its centre one body radius above the surface
    tip = next(x for x in out["contacts"] if x["obstacle"] == "table")
    assert tip["s_mm"] == pytest.approx(160.0) and tip["normal"] == pytest.approx([0.0, 1.0, 0.0])
    assert tip["position_mm"][1] == pytest.approx(1e3 * (TABLE_HEIGHT + RADIUS), abs=1e3 * GAP_ATOL)
    np.testing.assert_allclose(out["tip_position_mm"], tip["position_mm"], rtol=0, atol=1e-9)
    # the robot is in equilibrium: base load = weight + the contact forces on the robot
    pushed = sum(x["force_N"] * np.asarray(x["normal"]) for x in out["contacts"])
    on_obstacles = sum(np.asarray(w["force_N"]) for w in out["obstacles"])
    np.testing.assert_allclose(on_obstacles, -pushed, rtol=0, atol=BALANCE_ATOL)
    robot = tdct.Robot.paper()
    (section,), (tube,) = robot.sections, robot.tubes  # the body with its four tendon channels, the tube to 60 mm
    mass = section.density * section_area(section, robot.n_tendons) * robot.length + tube.density * tube.area * 0.06
    np.testing.assert_allclose(
        np.asarray(sol.total_force)[0], mass * np.asarray(STANDARD_GRAVITY) + pushed, rtol=0, atol=BALANCE_ATOL
    )
    assert [w["obstacle"] for w in out["obstacles"]] == ["table", "ball"]


def test_text_output_and_plot_show_the_contacts(tmp_path, capsys):
    png = tmp_path / "scene.png"
    assert main([*SOLVE, "--plot", str(png)]) == 0
    text = capsys.readouterr().out
    assert "contacts:          ball at s = " in text and "table at s = 160.0 mm, (" in text
    assert "on table:          force (" in text and "on ball:" in text
    assert png.stat().st_size > 20_000


@pytest.mark.parametrize(
    ("scene", "words"),
    [
        (
            '[[obstacles]]\nkind = "sphere"\nname = "ball"\ncenter = [0, -0.03, 0.09]\nradius = -0.015\n',
            "sphere 'ball' radius = -0.015",
        ),
        ('[[obstacles]]\nkind = "plane"\nname = "wall"\npoint = [0, 0, 0.3]\nnormal = [0, 0, 0]\n', "plane 'wall' normal"),
        (
            '[[obstacles]]\nkind = "capsule"\na = [0, 0.05, 0]\nb = [0, 0.05, 0.1]\nradius = 0.01\nlength = 2\n',
            "unknown field(s) ['length']",
        ),
        ('[[obstacles]]\nkind = "sphere"\ncenter = [0, -0.03, 0.09]\n', "obstacles[0] (sphere) lacks ['radius']"),
        ('[[obstacles]]\nkind = "box"\n', "obstacles[0] kind = 'box' must be one of"),
        (
            '[[obstacles]]\nkind = "sphere"\nname = "core"\ncenter = [0, 0, 0.005]\nradius = 0.01\n',
            "obstacles[0] (sphere 'core'): the robot's base",
        ),
        ("every = 0\n[[obstacles]]\nkind = 'plane'\npoint = [0, -0.05, 0]\nnormal = [0, 1, 0]\n", "every"),
    ],
)
@pytest.mark.parametrize(("verb", "solver"), [("solve", "solve"), ("compliance", "compliance_and_solution")])
def test_bad_scene_file_exits_2_naming_the_obstacle_and_field(verb, solver, scene, words, tmp_path, capsys, monkeypatch):
    def no_solve(*args, **kwargs):
        raise AssertionError("a solve started")

    monkeypatch.setattr(cli, solver, no_solve)
    path = tmp_path / "scene.toml"
    path.write_text(scene)
    assert main([verb, "--scene", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("tdct: error: ") and words in err and str(path) in err and "Traceback" not in err


def test_plot_draws_planes_spheres_capsules_and_contact_forces():
    """A straight shape drawn without a solve, touching a sphere at mid-length and a plane at the
    tip: each obstacle appears in the views that can show it, each contact force as an arrow."""
    robot = tdct.Robot(0.2, (tdct.Section(end=0.2, outer_diameter=0.02, E=1e6, nu=0.5, density=1e3),))
    scene = tdct.Scene(
        (
            tdct.Plane((0.0, 0.0, 0.21), (0.0, 0.0, -1.0), name="wall"),
            tdct.Sphere((0.0, -0.02, 0.1), 0.01, name="ball"),
            tdct.Capsule((-0.05, 0.05, 0.05), (0.05, 0.05, 0.05), 0.01, name="rail"),
        )
    )
    s = np.linspace(0.0, 0.2, 21)
    force = np.zeros((2, 3))
    force[0, 1], force[1, 0] = 0.3, 0.5  # the ball at s = 0.1, the wall at the tip
    normal = np.broadcast_to([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]], (2, 3, 3))
    contact = SimpleNamespace(
        s=np.array([0.1, 0.2]), position=np.outer([0.1, 0.2], [0, 0, 1.0]), force=force, normal=normal, active=force > 0
    )
    sol = SimpleNamespace(
        s=s,
        position=np.outer(s, [0.0, 0.0, 1.0]),
        rotation=np.broadcast_to(np.eye(3), (21, 3, 3)),
        tip_angle=0.0,
        contact=contact,
    )
    fig = plotting.plot_robot(sol, robot, None, tdct.Loads(scene=scene))
    side, top, ax3 = fig.axes
    for view, proxies in ((side, 1), (top, 0)):
        assert len(view.patches) == 3 + proxies  # the wall's solid side, the ball's and the rail's outlines
        assert len([a for a in view.texts if getattr(a, "arrow_patch", None)]) == 2  # the two contact forces
        assert {t.get_text() for t in view.texts} >= {"wall", "ball", "rail"}
    # the wall's trace across z = 210 mm in both flat views
    (trace,) = [line for line in side.get_lines() if type(line).__name__ == "AxLine"]
    assert trace.get_xy1()[0] == pytest.approx(210.0)
    assert len(ax3.collections) >= 4  # the wall, the ball, the rail's cylinder and its ends
    matplotlib.pyplot.close(fig)
