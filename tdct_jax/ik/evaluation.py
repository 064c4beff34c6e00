"""One IK evaluation: a converged forward solve at the scaled inputs v with the task residual, the
objective and their exact derivatives in v."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from .. import general
from ..inputs import GeneralActuation
from ..shooting import compliance_at, force_scale, root, scaled, shoot, unscaled
from ..solve import solution_and_compliance
from .objectives import objective_value
from .problem import Plan, Problem, _wrench, actuation_of, task_residual


class Evaluation(NamedTuple):
    """A converged forward solve at v and what the IK needs of it."""

    e: jax.Array  # task residual
    G: jax.Array  # de/dv
    phi: jax.Array  # objective (0 without one)
    dphi: jax.Array  # d phi / dv
    wrench: jax.Array  # base wrench, the next solve's start
    code: jax.Array  # the forward solve's status code


def evaluate(v, guess, prob: Problem, plan: Plan) -> Evaluation:
    """Forward solve at v (from ``guess``) with the task residual, the objective and their exact
    derivatives in v (forward mode through the implicitly differentiated root). Only the root and
    one integration to the tip are differentiated: a user's objective, which sees the whole
    Solution, adds the path."""

    def f(v):
        act = actuation_of(v, prob, plan)
        problem = (prob.robot, act, prob.load, prob.gravity)
        F_c = force_scale(*problem)
        if callable(plan.objective):
            sol = solution_and_compliance(*problem, guess, prob.solver)[0]
            x, code, p, R = scaled(prob.robot, _wrench(sol, act), F_c), sol.result, sol.tip_position, sol.tip_rotation
        else:
            sol, (x, info) = None, root(*problem, guess, prob.solver)
            tip = shoot(*problem, prob.solver, x, F_c)[1]
            code, p, R = info.result, tip.p, tip.R
        e = task_residual(p, R, prob.target, prob.robot.length)
        C = compliance_at(*problem, prob.solver, x) if plan.objective == "stiffness" else None
        pulled = general.with_driven(act, x, F_c) if isinstance(act, GeneralActuation) else act  # the driven tensions found
        phi = jnp.zeros(()) if plan.objective is None else objective_value(sol, C, pulled, prob, plan)
        return (e, phi), (e, phi, unscaled(prob.robot, x, F_c), code)

    (G, dphi), (e, phi, wrench, code) = jax.jacfwd(f, has_aux=True)(v)
    return Evaluation(e, G, phi, dphi, wrench, code)
