"""Single or multiple shooting: the one place ``SolverOptions.intervals`` chooses between them."""

from __future__ import annotations

from . import multiple, shooting


def root(robot, act, load, gravity, guess, solver):
    """The scaled unknowns x (shooting.py) with a zero residual and RootInfo, with implicit
    derivatives: by multiple shooting (``multiple.root``) where ``solver.intervals`` > 1 (the same
    root, RootInfo's Jacobians single shooting's), else by single shooting (``shooting.root``)."""
    if solver.intervals > 1:
        u, info = multiple.root(robot, act, load, gravity, guess, solver)
        return u.x, info
    return shooting.root(robot, act, load, gravity, guess, solver)


def path(robot, act, load, gravity, guess, solver):
    """``root``, then the residual and the path along the robot there, as ``rod.shoot`` gives
    them: (x, RootInfo, residual, path). Multiple shooting's path comes from its intervals side
    by side."""
    if solver.intervals > 1:
        u, info = multiple.root(robot, act, load, gravity, guess, solver)
        return (u.x, info, *multiple.path(robot, act, load, gravity, solver, u))
    x, info = shooting.root(robot, act, load, gravity, guess, solver)
    F_c = shooting.force_scale(robot, act, load, gravity)
    return (x, info, *shooting.shoot(robot, act, load, gravity, solver, x, F_c, path=True))
