import os

import jax
import numpy as np
import pytest

import tdct_jax as tdct

os.environ["TDCT_COMPILE_CACHE"] = "0"  # tests compile afresh: no persistent cache from the CLI, here or in subprocesses
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")

NO_GRAVITY = None


def rel_err(a, b):
    """Largest relative deviation of a from the reference b."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.fixture(scope="session")
def robot():
    return tdct.Robot()


@pytest.fixture(scope="session")
def paper_case(robot):
    """The paper's Fig. 6 setting: 6 N on tendon 1, 80 mm of tube, 20 g at the tip."""
    act = tdct.Actuation(tensions=(6.0, 0.0, 0.0, 0.0), insertion=0.08)
    load = tdct.TipLoad.from_mass(0.020)
    return robot, act, load, tdct.solve(robot, act, load, throw=True)
