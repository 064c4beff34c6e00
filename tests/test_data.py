"""Shape files: the documented format reads, round trips, and every bad file gets a path:line error."""

import dataclasses

import jax
import numpy as np
import pytest

import tdct_jax as tdct
from tdct_jax import data

# Lines: 1 version, 2 name, 3 tensions, 4 insertion, 5 tip mass, 6 columns, 7-9 points.
BASE = """\
# tdct_jax shape v1
# name: base
# tensions_N: 6, 0, 0, 0
# insertion_mm: 80
# tip_mass_g: 20
s_mm,x_mm,y_mm,z_mm
0,0,0,0
5,0,-0.1,5
10,0,-0.4,10
"""


def shape_file(tmp_path, old=None, new=None, name="shape.csv"):
    """BASE (with ``old`` replaced by ``new``) written to a file."""
    text = BASE if old is None else BASE.replace(old, new)
    assert text != BASE or old is None, f"{old!r} is not in BASE"
    path = tmp_path / name
    path.write_text(text)
    return path


def expect_error(path, line, words, robot=None):
    with pytest.raises(ValueError) as e:
        data.read_experiment(path, robot)
    message = str(e.value)
    prefix = f"{path}:{line}: " if line else f"{path}: "
    assert message.startswith(prefix), message
    for w in words:
        assert w in message, f"{w!r} not in {message!r}"
    return message


def assert_same(a, b, rtol=1e-9):
    assert a.name == b.name
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=rtol, atol=0)


def helix(n=31, length=0.15):
    """A unit-speed helix from the base along +z (so every point is within its arc length)."""
    s = np.linspace(0.0, length, n)
    a, k = 0.02, 10.0
    c = np.sqrt(1 - (a * k) ** 2)
    return s, np.column_stack([a * np.cos(k * s) - a, a * np.sin(k * s), c * s])


def test_documented_example_reads(tmp_path):
    path = tmp_path / "example.csv"
    path.write_text(data.FORMAT)
    exp = data.read_experiment(path)
    assert exp.name == "t1-6N_d80mm_m20g" and exp.n_points == 3
    np.testing.assert_allclose(exp.act.tensions, [6, 0, 0, 0])
    np.testing.assert_allclose(exp.act.insertion, 0.080)
    np.testing.assert_allclose(exp.tip_mass, 0.020)
    np.testing.assert_allclose(exp.s, [0, 0.005, 0.010])
    np.testing.assert_allclose(exp.position[1], [1e-5, -2e-5, 4.999e-3])
    np.testing.assert_allclose(exp.weight, 1.0)
    assert "tdct_jax shape v1" in data.__doc__ and "tensions_N" in data.__doc__


def test_defaults_comments_and_extra_columns(tmp_path):
    path = tmp_path / "run 7.csv"
    path.write_text(
        "# FBG export, recorded 2024-05-01 10.30\n# tensions_N: 1 2 0 0\n\n"
        "time,z_mm,s_mm,y_mm,x_mm,note\n0.1,0,0,0,0,start\n0.2,20,20,0,0.5,\n"
    )
    exp = data.read_experiment(path)
    assert exp.name == "run 7"
    np.testing.assert_allclose(exp.act.tensions, [1, 2, 0, 0])
    assert float(exp.act.insertion) == 0 and float(exp.tip_mass) == 0
    np.testing.assert_allclose(exp.load.tip_force, 0.0)
    np.testing.assert_allclose(exp.position[1], [0.0005, 0.0, 0.020])


def test_round_trip(tmp_path):
    s, position = helix()
    exp = data.Experiment(
        s=s,
        position=position,
        act=tdct.Actuation((6.0, 0.25, 0.0, 1.5), 0.0437),
        load=tdct.Loads(tip_force=(0.01, -0.2, 0.03), tip_moment=(1e-3, 0.0, -2.5e-4)),
        tip_mass=0.0123,
        name="helix t1 6N",
    )
    path = data.write_experiment(tmp_path / "new" / "folder" / "helix.csv", exp)
    assert path.exists() and path.read_text().startswith("# tdct_jax shape v1\n# name: helix t1 6N\n")
    assert_same(data.read_experiment(path), exp)


def test_writer_refuses_what_the_format_cannot_hold(tmp_path):
    s, position = helix(5)
    exp = data.Experiment(s, position, tdct.Actuation())
    with pytest.raises(ValueError, match="weight"):
        data.write_experiment(tmp_path / "w.csv", data.Experiment(s, position, tdct.Actuation(), weight=[1, 1, 1, 1, 0.5]))
    with pytest.raises(ValueError, match="one line"):
        data.write_experiment(tmp_path / "n.csv", data.Experiment(s, position, tdct.Actuation(), name="a\nb"))
    with pytest.raises(ValueError, match="index the stack"):
        data.write_experiment(tmp_path / "st.csv", data.stack([exp, exp]))


@pytest.mark.parametrize("kind", ["missing", "directory", "not utf-8"])
def test_unreadable_file(tmp_path, kind):
    path = tmp_path / "shape.csv"
    if kind == "directory":
        path.mkdir()
    elif kind == "not utf-8":
        path.write_bytes(b"\xff\xfe\x00s\x00_\x00m\x00m")
    words = {"missing": ["No such file"], "directory": ["directory"], "not utf-8": ["not UTF-8", "byte 0"]}[kind]
    expect_error(path, 0, ["cannot read shape file", *words])


def test_missing_columns(tmp_path):
    path = shape_file(tmp_path, "s_mm,x_mm,y_mm,z_mm", "s,x_mm,y_mm")
    expect_error(path, 6, ["missing column(s) ['s_mm', 'z_mm']", "found columns ['s', 'x_mm', 'y_mm']"])


def test_no_column_line(tmp_path):
    path = tmp_path / "header_only.csv"
    path.write_text("# tensions_N: 0, 0, 0, 0\n")
    expect_error(path, 0, ["no column line", "s_mm,x_mm,y_mm,z_mm"])


@pytest.mark.parametrize(
    "new, words",
    [
        ("5,0,-0.1", ["3 fields", "column line has 4"]),
        ("5,0,-0.1,5,7", ["5 fields"]),
        ("5,0,abc,5", ["y_mm = 'abc' is not a number"]),
        ("5,0,-0.1,", ["z_mm = '' is not a number"]),
    ],
)
def test_bad_row(tmp_path, new, words):
    expect_error(shape_file(tmp_path, "5,0,-0.1,5", new), 8, words)


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_non_finite_value(tmp_path, value):
    expect_error(shape_file(tmp_path, "5,0,-0.1,5", f"5,{value},-0.1,5"), 8, [f"x_mm = {value} is not finite"])


def test_arc_length_not_increasing(tmp_path):
    path = shape_file(tmp_path, "10,0,-0.4,10", "5,0,-0.4,10")
    expect_error(path, 9, ["s_mm = 5 does not increase on line 8's s_mm = 5", "strictly increasing"])


def test_arc_length_negative(tmp_path):
    path = shape_file(tmp_path, "0,0,0,0", "-1,0,0,0")
    expect_error(path, 7, ["s_mm = -1 is negative", ">= 0"])


def test_fewer_than_two_rows(tmp_path):
    path = shape_file(tmp_path, "5,0,-0.1,5\n10,0,-0.4,10\n", "")
    expect_error(path, 0, ["1 data row(s)", "at least 2 points"])


@pytest.mark.parametrize(
    "old, new, line, words",
    [
        ("# tensions_N: 6, 0, 0, 0\n", "", 0, ["missing header line '# tensions_N: ...'", "4 for this robot"]),
        ("6, 0, 0, 0", "6, 0, 0", 3, ["tensions_N = '6, 0, 0' has 3 value(s), expected 4", "4 tendons"]),
        ("6, 0, 0, 0", "6, -1, 0, 0", 3, ["tensions_N", "-1", "[0, inf] N"]),
        ("insertion_mm: 80", "insertion_mm: 170", 4, ["insertion_mm = 170", "[0, 160] mm"]),
        ("insertion_mm: 80", "insertion_mm: -2", 4, ["insertion_mm = -2", "[0, 160] mm"]),
        ("tip_mass_g: 20", "tip_mass_g: -20", 5, ["tip_mass_g = -20", "[0, inf] g"]),
        ("tip_mass_g: 20", "tip_mass_g: 20g", 5, ["tip_mass_g = '20g' is not a number"]),
        ("tip_mass_g: 20", "tip_mass_g: nan", 5, ["tip_mass_g = nan is not finite"]),
        ("tip_mass_g: 20", "tip_mass_g:", 5, ["tip_mass_g = '' has 0 value(s), expected 1"]),
        ("tip_mass_g: 20", "tip_mass_g: 20\n# tip_force_N: 0, 1", 6, ["tip_force_N = '0, 1' has 2 value(s), expected 3"]),
        ("tip_mass_g: 20", "tip_mas_g: 20", 5, ["unknown header key 'tip_mas_g'", "did you mean 'tip_mass_g'", "tip_moment_Nmm"]),
        ("tip_mass_g: 20", "tip_mass_g: 20\n# tip_mass_g: 30", 6, ["duplicate header key 'tip_mass_g'", "line 5"]),
        ("# tdct_jax shape v1", "# tdct_jax shape v2", 1, ["version '2' is not supported"]),
    ],
)
def test_bad_header(tmp_path, old, new, line, words):
    expect_error(shape_file(tmp_path, old, new), line, words)


def test_tension_count_follows_the_robot(tmp_path):
    three = tdct.Robot.paper(tendon_angles=(0.0, 2.0, 4.0))
    expect_error(shape_file(tmp_path), 3, ["has 4 value(s), expected 3", "3 tendons"], robot=three)
    exp = data.read_experiment(shape_file(tmp_path, "6, 0, 0, 0", "6, 0, 0"), three)
    assert exp.act.tensions.shape == (3,)


@pytest.mark.parametrize(
    "old, new, line, words",
    [
        ("10,0,-0.4,10", "170,0,-0.4,10", 9, ["s_mm = 170 mm is beyond the robot length 160 mm", "164.2", "millimetres (s_mm)"]),
        (
            "10,0,-0.4,10",
            "10,0,-0.4,200",
            9,
            ["distance of a point from the base = 200 mm", "millimetres (x_mm, y_mm, z_mm), in the robot base frame"],
        ),
        ("5,0,-0.1,5\n10,0,-0.4,10", "0.005,0,-0.0001,0.005\n0.01,0,-0.0004,0.01", 9, ["millimetres (s_mm)", "look like metres"]),
        ("5,0,-0.1,5\n10,0,-0.4,10", "5,0,-0.0001,0.005\n10,0,-0.0004,0.01", 9, ["millimetres (x_mm, y_mm, z_mm)", "metres"]),
    ],
)
def test_units_out_of_range(tmp_path, old, new, line, words):
    expect_error(shape_file(tmp_path, old, new), line, words)


def test_length_slack_and_robot(tmp_path):
    path = shape_file(tmp_path, "10,0,-0.4,10", "164,0,-0.4,164")  # within 160 mm + 2% + 1 mm
    assert data.read_experiment(path).n_points == 3
    expect_error(path, 9, ["robot length 100 mm"], robot=tdct.Robot.paper(length=0.1))


def test_read_experiments(tmp_path):
    folder = tmp_path / "shapes"
    folder.mkdir()
    for name in ("b", "a"):
        shape_file(folder, "name: base", f"name: {name}", name=f"{name}.csv")
    (folder / "notes.txt").write_text("not a shape")
    extra = shape_file(tmp_path, "name: base", "name: extra", name="extra.txt")
    exps = data.read_experiments([folder, extra])
    assert [e.name for e in exps] == ["a", "b", "extra"]
    assert [e.name for e in data.read_experiments(str(folder))] == ["a", "b"]
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="no shape files found"):
        data.read_experiments([empty])


def test_stack_pads_and_vmaps():
    s3, p3 = helix(3)
    s5, p5 = helix(5, 0.1)
    short = data.Experiment(s3, p3, tdct.Actuation((1.0, 0, 0, 0), 0.01), tip_mass=0.02, name="short")
    long = data.Experiment(s5, p5, tdct.Actuation((2.0, 0, 0, 0), 0.02), tdct.Loads(tip_force=(0.1, 0, 0)), name="long")
    st = data.stack([short, long])
    assert st.s.shape == (2, 5) and st.position.shape == (2, 5, 3) and st.weight.shape == (2, 5)
    assert st.act.tensions.shape == (2, 4) and st.tip_mass.shape == (2,) and st.name == ""
    np.testing.assert_array_equal(st.weight, [[1, 1, 1, 0, 0], [1, 1, 1, 1, 1]])
    np.testing.assert_array_equal(st.s[0], [*s3, s3[-1], s3[-1]])
    np.testing.assert_array_equal(st.position[0, 3:], [p3[-1], p3[-1]])
    force = jax.vmap(lambda e: e.tip_load().tip_force)(st)
    np.testing.assert_allclose(force, [[0, -0.02 * 9.81, 0], [0.1, 0, 0]], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(st.tip_load().tip_force, force)
    # one padded experiment taken back out of the stack passes the checks (repeats have weight 0)
    first = jax.tree_util.tree_map(lambda x: x[0], st)
    assert first.n_points == 5 and float(first.tip_mass) == 0.02


def test_stack_refuses_different_tendon_counts():
    s, p = helix(4)
    four = data.Experiment(s, p, tdct.Actuation((1.0, 0, 0, 0)), name="four")
    three = data.Experiment(s, p, tdct.Actuation((1.0, 0, 0)), name="three")
    with pytest.raises(ValueError, match=r"different numbers of tendons: #0 'four' has 4, #1 'three' has 3"):
        data.stack([four, three])
    with pytest.raises(ValueError, match="at least one"):
        data.stack([])


def test_experiment_is_a_pytree_and_tip_load_adds_the_weight():
    s, p = helix(6)
    exp = data.Experiment(s, p, tdct.Actuation((3.0, 0, 0, 0), 0.05), tdct.Loads(tip_force=(0.1, 0, 0)), tip_mass=0.02)
    np.testing.assert_allclose(jax.jit(lambda e: e.position.sum())(exp), p.sum())
    np.testing.assert_allclose(jax.jit(lambda e: e.tip_load().tip_force)(exp), [0.1, -0.02 * 9.81, 0.0])
    np.testing.assert_allclose(exp.tip_load(gravity=(0.0, 0.0, -10.0)).tip_force, [0.1, 0.0, -0.2])
    np.testing.assert_allclose(exp.tip_load(gravity=None).tip_force, [0.1, 0.0, 0.0])
    np.testing.assert_allclose(jax.grad(lambda m: dataclasses.replace(exp, tip_mass=m).tip_load().tip_force[1])(0.02), -9.81)
    np.testing.assert_allclose(exp.weight, np.ones(6))


@pytest.mark.parametrize(
    "change, words",
    [
        (dict(s=[0.0, 0.02, 0.01]), ["strictly increasing", "s[1] = 0.02", "s[2] = 0.01"]),
        (dict(s=[0.0, 0.01, 0.01]), ["strictly increasing", "weight 0"]),
        (dict(s=[-0.01, 0.0, 0.01]), ["s = ", "[0, inf] m"]),
        (dict(position=np.zeros((3, 2))), ["position must have shape (3, 3)"]),
        (dict(position=[[0, 0, 0], [0, np.nan, 0], [0, 0, 0]]), ["position must be finite"]),
        (dict(tip_mass=-0.1), ["tip_mass = -0.1", "[0, inf] kg"]),
        (dict(weight=[1.0, -1.0, 1.0]), ["weight", "[0, inf]"]),
        (dict(weight=[1.0, 1.0]), ["weight must have shape (3,)"]),
        (dict(s=np.zeros((1, 3))), ["s must have shape (n,)"]),
    ],
)
def test_bad_experiment(change, words):
    fields = dict(s=[0.0, 0.01, 0.02], position=np.zeros((3, 3)), act=tdct.Actuation()) | change
    with pytest.raises(ValueError) as e:
        data.Experiment(**fields)
    for w in words:
        assert w in str(e.value), str(e.value)


def test_writing_the_documented_example_back_gives_its_bytes(tmp_path):
    # the file format is unchanged: a read shape file written back is byte for byte the same
    path = tmp_path / "example.csv"
    path.write_text(data.FORMAT)
    exp = data.read_experiment(path)
    assert isinstance(exp.act, tdct.Actuation) and isinstance(exp.load, tdct.Loads)
    assert exp.act.insertions.shape == (1,) and exp.load.n_points == 0
    assert data.write_experiment(tmp_path / "again.csv", exp).read_text() == data.FORMAT


def test_a_robot_without_a_tube_reads_and_writes_shape_files(tmp_path):
    robot = dataclasses.replace(tdct.Robot.paper(), tubes=())
    exp = data.read_experiment(shape_file(tmp_path, "# insertion_mm: 80\n", ""), robot)
    assert exp.act.insertions.shape == (0,)
    written = data.write_experiment(tmp_path / "back.csv", exp)
    assert "# insertion_mm: 0\n" in written.read_text()
    assert_same(data.read_experiment(written, robot), exp)
    expect_error(shape_file(tmp_path), 4, ["insertion_mm = 80", "no tube"], robot=robot)
    two = tdct.Robot.from_toml("tdct_jax/robots/two_segment.toml")
    six = data.read_experiment(shape_file(tmp_path, "6, 0, 0, 0\n# insertion_mm: 80", "6, 0, 0, 0, 0, 0"), two)
    assert six.act.tensions.shape == (6,) and six.act.insertions.shape == (0,)
    tube = tdct.Robot.paper().tubes[0]
    inner = dataclasses.replace(tube, outer_diameter=0.001, inner_diameter=0.0005)
    many = dataclasses.replace(tdct.Robot.paper(), tubes=(tube, inner))
    expect_error(shape_file(tmp_path), 0, ["2 tubes", "one tube's insertion"], robot=many)


def test_writer_refuses_actuations_and_loads_beyond_the_format(tmp_path):
    s, position = helix(5)
    cases = [
        (tdct.Actuation((0.0, 0, 0, 0), driven=(1,), displacements=(1e-3,)), tdct.Loads(), "displacement-driven"),
        (tdct.Actuation((1.0, 0, 0, 0), (0.01, 0.02)), tdct.Loads(), "2 tube insertions"),
        (tdct.Actuation((1.0, 0, 0, 0), 0.01), tdct.Loads(point_s=(0.05,), point_force=((0, 0.1, 0),)), "1 point load"),
        (tdct.Actuation((1.0, 0, 0, 0), 0.01), tdct.Loads(distributed_force=(0, 1.0, 0)), "distributed force"),
    ]
    for act, load, words in cases:
        with pytest.raises(ValueError, match=words):
            data.write_experiment(tmp_path / "x.csv", data.Experiment(s, position, act, load))


def test_stack_holds_actuations_and_loads_with_batch_axes():
    s, p = helix(4)
    point = tdct.Loads(point_s=(0.05,), point_force=((0, 0.1, 0),))
    a = data.Experiment(s, p, tdct.Actuation((1.0, 0, 0, 0), 0.01), point, name="a")
    b = data.Experiment(s, p, tdct.Actuation((2.0, 0, 0, 0), 0.02), dataclasses.replace(point, point_s=(0.07,)), name="b")
    st = data.stack([a, b])
    assert st.act.tensions.shape == (2, 4) and st.act.insertions.shape == (2, 1)
    assert st.load.point_s.shape == (2, 1) and st.load.point_force.shape == (2, 1, 3) and st.load.tip_force.shape == (2, 3)
    np.testing.assert_array_equal(st.act.insertion, [0.01, 0.02])
    # a stacked Actuation and Loads built by hand (leading batch axes) make a stacked Experiment too
    by_hand = data.Experiment(
        np.stack([s, s]), np.stack([p, p]), tdct.Actuation(st.act.tensions, st.act.insertions), tdct.Loads.from_mass([0.0, 0.01])
    )
    assert by_hand.tip_mass.shape == (2,) and by_hand.tip_load().tip_force.shape == (2, 3)
    with pytest.raises(ValueError, match="different numbers of point loads"):
        data.stack([a, data.Experiment(s, p, tdct.Actuation((1.0, 0, 0, 0), 0.01), name="c")])
    with pytest.raises(ValueError, match="different numbers of tube insertions"):
        data.stack([a, data.Experiment(s, p, tdct.Actuation((1.0, 0, 0, 0)), point, name="d")])
    with pytest.raises(ValueError, match="same driven"):
        data.stack([a, data.Experiment(s, p, tdct.Actuation((1.0, 0, 0, 0), 0.01, (1e-3,), (0,)), point, name="e")])
