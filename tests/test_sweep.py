"""Batched sweeps: equal to one-by-one solves, warm starts, outputs, files, bad input, 2 devices,
chunks streamed to the caller and to .npz files, parts of a multi-process sweep gathered."""

import json
import os
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest

import tdct_jax as tdct

STEPS = tdct.SolverOptions().steps

BASE = tdct.Actuation((6.0, 0.0, 0.0, 2.0), 0.0)
GRID = {"insertion": np.array([0.0, 0.08, 0.16]), "tip_mass": np.array([0.0, 0.03])}


@pytest.fixture(scope="module")
def grid_sweep(robot):
    return tdct.sweep(robot, BASE, grid=GRID, progress=False)


def test_grid_sweep_equals_one_by_one_solves(robot, grid_sweep):
    res = grid_sweep
    assert res.shape == (3, 2) and res.n_failed == 0
    for i, d in enumerate(GRID["insertion"]):
        for j, m in enumerate(GRID["tip_mass"]):
            single = tdct.solve(robot, tdct.Actuation(BASE.tensions, d), tdct.Loads.from_mass(m))
            # the batch engine's first pass is a quasi-Newton method: the same root, to the tolerance
            np.testing.assert_allclose(res.tip_position[i, j], single.tip_position, rtol=0, atol=1e-9)
            np.testing.assert_allclose(res.tip_angle[i, j], single.tip_angle, rtol=0, atol=1e-8)
            assert res.result[i, j] == single.result
    np.testing.assert_array_equal(res.inputs["insertion"][:, 1], GRID["insertion"])


@pytest.mark.slow
def test_batch_of_robot_fields_zips_points(robot):
    batch = {"sections[*].E": np.array([0.7e6, 1.1e6]), "insertion": np.array([0.02, 0.12])}
    res = tdct.sweep(robot, BASE, batch=batch, shapes=True, compliance=True, progress=False)
    assert res.shape == (2,) and res.position.shape == (2, 2 * (STEPS + 1), 3)
    for k in range(2):
        r = tdct.Robot.paper(E_silicone=batch["sections[*].E"][k])
        act = tdct.Actuation(BASE.tensions, batch["insertion"][k])
        np.testing.assert_allclose(res.position[k], tdct.solve(r, act).position, rtol=0, atol=1e-9)
        np.testing.assert_allclose(res.compliance[k], tdct.compliance(r, act), rtol=1e-9)


# three paths of six tensions, one path per compiled call (the parts test splits the three chunks
# between two processes): both tests run one compiled program
WARM = dict(
    grid={"insertion": np.array([0.0, 0.05, 0.1]), "tensions": np.outer(np.linspace(0.0, 10.0, 6), [1.0, 0.0, 0.0, 0.0])},
    warm_start=True,
    chunk_size=1,
    progress=False,
)


@pytest.mark.slow
def test_warm_started_path_matches_cold_solves(robot):
    grid = WARM["grid"]
    cold = tdct.sweep(robot, grid=grid, progress=False)
    warm = tdct.sweep(robot, **WARM)
    assert warm.n_failed == 0
    np.testing.assert_allclose(warm.tip_position, cold.tip_position, rtol=0, atol=1e-9)
    print(f"Newton iterations along the tension path: cold {cold.iterations.sum()}, warm {warm.iterations.sum()}")


def test_results_save_to_npz_and_csv(grid_sweep, tmp_path):
    res = grid_sweep
    data = np.load(res.save_npz(tmp_path / "s.npz"))
    np.testing.assert_array_equal(data["tip_position"], res.tip_position)
    np.testing.assert_array_equal(data["axis_tip_mass"], GRID["tip_mass"])
    lines = res.save_csv(tmp_path / "s.csv").read_text().splitlines()
    header = lines[0].split(",")
    assert header[:2] == ["insertion_m", "tip_mass_kg"] and "tip_y_m" in header and len(lines) == 7
    table = np.loadtxt(tmp_path / "s.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(table[:, header.index("tip_y_m")], res.tip_position[..., 1].ravel(), rtol=1e-15)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(grid={"stiffness": [1.0]}), "cannot sweep 'stiffness'"),
        (dict(grid={"insertion": [0.0, 0.2]}), "insertion[1] = 0.2 is outside the allowed range [0, 0.16]"),
        (dict(grid={"tensions": [[1.0, 0.0, 0.0]]}), "tensions: each point must have shape (4,)"),
        (
            dict(grid={"tensions": [[-1.0, 0.0, 0.0, 0.0]]}),
            "tensions[0] = [-1.,  0.,  0.,  0.] is outside the allowed range [0, inf]",
        ),
        (dict(grid={"tip_mass": [np.nan]}), "tip_mass must be finite"),
        (dict(grid={"sections[*].E": [-1.0]}), "sections[0].E = -1 is outside the allowed range (0, inf]"),
        (dict(batch={"insertion": [0.0, 0.1], "tip_mass": [0.0]}), "same number of points"),
        (dict(batch={"insertion": [0.0]}, warm_start=True), "warm_start=True needs grid="),
        (dict(), "give exactly one of grid="),
        (dict(grid={"insertion": [0.0]}, chunk_size=0), "chunk_size = 0"),
        (dict(grid={"insertion": []}), "insertion: no values (an empty list); give at least one point"),
        (dict(batch={"insertion": [0.0], "tip_mass": []}), "tip_mass: no values"),
        (
            dict(
                grid={name: np.linspace(0.002, 0.005, 1000) for name in ("insertion", "tip_mass", "tendon_offset", "nu_silicone")}
            ),
            "a grid of 1000 x 1000 x 1000 x 1000 = 1,000,000,000,000 points needs about",
        ),
        (dict(grid={"insertion": [0.0]}, out="x.csv"), "out = 'x.csv': .csv is not a sweep's file format"),
        (dict(grid={"insertion": [0.0]}, out="/proc/x.npz"), "out = '/proc/x.npz': cannot write a file in /proc"),
    ],
)
def test_bad_sweep_input_names_the_field(robot, kwargs, message):
    with pytest.raises(ValueError) as e:
        tdct.sweep(robot, progress=False, **kwargs)
    assert message in str(e.value)


@pytest.mark.slow
def test_sharded_sweep_on_two_devices_equals_one_device():
    script = textwrap.dedent(
        """
        import json, jax, numpy as np, tdct_jax as tdct
        assert jax.device_count() == 2, jax.devices()
        grid = {"insertion": np.linspace(0.0, 0.16, 3), "tensions": np.outer([0.0, 4.0, 9.0], [1.0, 0.0, 0.0, 0.5])}
        two = tdct.sweep(tdct.Robot.paper(), grid=grid, progress=False)
        one = tdct.sweep(tdct.Robot.paper(), grid=grid, progress=False, devices=jax.devices()[:1])
        print(json.dumps(dict(two=two.tip_position.tolist(), one=one.tip_position.tolist(), failed=two.n_failed)))
        """
    )
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    run = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    out = json.loads(run.stdout.strip().splitlines()[-1])
    assert out["failed"] == 0
    np.testing.assert_allclose(out["two"], out["one"], rtol=0, atol=1e-15)


# 6 points: a full chunk and a padded one
STREAM = dict(grid=GRID, chunk_size=4, solver=tdct.SolverOptions(steps=4), progress=False)


@pytest.fixture(scope="module")
def small_chunk_sweep(robot):
    return tdct.sweep(robot, BASE, **STREAM)


def assert_same_sweep(a, b):
    """Every array of two SweepResults equal bit for bit, with the same dtypes."""
    assert a.shape == b.shape and a.inputs.keys() == b.inputs.keys() and (a.axes or {}).keys() == (b.axes or {}).keys()
    pairs = [(a.inputs[k], b.inputs[k]) for k in a.inputs] + [(a.axes[k], b.axes[k]) for k in a.axes or {}]
    pairs += [(getattr(a, f), getattr(b, f)) for f in ("tip_position", "tip_rotation", "converged", "iterations")]
    pairs += [(getattr(a, f), getattr(b, f)) for f in ("residual_norm", "base_wrench", "s", "position", "compliance")]
    for x, y in pairs:
        assert (x is None) == (y is None)
        if x is not None:
            assert x.dtype == y.dtype
            np.testing.assert_array_equal(x, y, strict=True)


def test_streamed_npz_equals_the_in_memory_sweep(robot, small_chunk_sweep, tmp_path):
    path = tdct.sweep(robot, BASE, out=tmp_path / "s.npz", **STREAM)
    assert path == tmp_path / "s.npz" and sorted(p.name for p in tmp_path.iterdir()) == ["s.npz"]  # no leftovers
    assert_same_sweep(tdct.gather(path), small_chunk_sweep)
    streamed, saved = np.load(path), np.load(small_chunk_sweep.save_npz(tmp_path / "saved.npz"))
    assert sorted(streamed.files) == sorted(saved.files)
    for k in saved.files:
        np.testing.assert_array_equal(streamed[k], saved[k], strict=True)


def test_chunks_arrive_in_order_and_join_to_the_sweep(robot, small_chunk_sweep):
    res = small_chunk_sweep
    chunks = list(tdct.sweep_chunks(robot, BASE, **STREAM))
    assert [(c.start, c.stop) for c in chunks] == [(0, 4), (4, 6)]
    for name in ("tip_position", "iterations"):
        joined = np.concatenate([c.outputs[name] for c in chunks])
        np.testing.assert_array_equal(joined, getattr(res, name).reshape(joined.shape), strict=True)
    index = np.unravel_index(np.arange(4, 6), res.shape)  # the second chunk's grid indices
    np.testing.assert_array_equal(chunks[1].inputs["tip_mass"], GRID["tip_mass"][index[1]])
    np.testing.assert_array_equal(chunks[1].inputs["insertion"], GRID["insertion"][index[0]])


def test_parts_of_a_warm_started_sweep_gather_to_the_whole(robot, tmp_path, monkeypatch):
    """Two processes, simulated in this one: each writes its paths; gather joins them."""
    whole = tdct.sweep(robot, **WARM)
    for k in range(2):
        monkeypatch.setattr(jax, "process_count", lambda: 2)
        monkeypatch.setattr(jax, "process_index", lambda k=k: k)
        with pytest.raises(ValueError, match="needs out="):
            tdct.sweep(robot, **WARM)
        assert tdct.sweep(robot, out=tmp_path / "w.npz", **WARM).name == f"w.part{k}-of-2.npz"
    monkeypatch.undo()
    assert_same_sweep(tdct.gather(tmp_path / "w.npz"), whole)
    with pytest.raises(ValueError, match="holds one part"):
        tdct.gather(tmp_path / "w.part1-of-2.npz")
    (tmp_path / "w.part1-of-2.npz").unlink()
    with pytest.raises(ValueError, match=r"1 of 2 parts are missing or unfinished: part 1 \(no file, no partial folder\)"):
        tdct.gather(tmp_path / "w.npz")
    with pytest.raises(ValueError, match="no such file, nor any part"):
        tdct.gather(tmp_path / "none.npz")
