"""Figures (the only module that imports matplotlib). Axes in millimetres and degrees.

Every figure is drawn under ``STYLE`` (font sizes readable on a slide, matplotlib's mathtext for
symbols such as the labels in ``LABEL``); the user's own rcParams are left as they were.
"""

from __future__ import annotations

import functools
from pathlib import Path

import jax
import numpy as np

from .solve import Solution

STYLE = {
    "font.size": 12,
    "axes.titlesize": 13,
    "axes.labelsize": 13,
    "xtick.labelsize": 11.5,
    "ytick.labelsize": 11.5,
    "legend.fontsize": 11,
    "legend.title_fontsize": 11.5,
    "figure.titlesize": 14,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "savefig.dpi": 130,
}
"""rcParams every figure of this module is drawn with: the one place its fonts are set."""
LABEL = dict(
    z_tip=r"$z_{\mathrm{tip}}$ [mm]",
    y_tip=r"$y_{\mathrm{tip}}$ [mm]",
    theta_tip=r"$\theta_{\mathrm{tip}}$ [deg]",
    z=r"$z$ [mm]",
    y=r"$y$ [mm]",
    insertion=r"insertion depth $d$ [mm]",
    target_height=r"target tip height $y_{\mathrm{tip}}$ [mm]",
    compliance_down=r"tip compliance along $-y$ [mm/N]",
)
"""Axis labels used by several figures, in mathtext."""


def _pyplot():
    import matplotlib

    if "inline" not in matplotlib.get_backend():  # keep Jupyter's inline figures
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _styled(plot):
    """Draws ``plot`` (a function of this module) under STYLE, without touching global rcParams."""

    @functools.wraps(plot)
    def styled(*args, **kwargs):
        with _pyplot().rc_context(STYLE):
            return plot(*args, **kwargs)

    return styled


def _finish(fig, path):
    """Saves the figure as a PNG when a path is given (and closes it); returns it either way."""
    if fig.get_layout_engine() is None:
        fig.tight_layout()
    if path is not None:
        fig.savefig(path)
        _pyplot().close(fig)
    return fig


def _starts(s) -> np.ndarray:
    """True at the nodes that start an interval: the base and the right side of each breakpoint
    (nodes come interval by interval, both sides of every breakpoint at the same arc length)."""
    s = np.asarray(s)
    return np.r_[True, np.diff(s) <= 0] if s.size else np.zeros(0, bool)


def _upto(s, x) -> np.ndarray:
    """True at the nodes of the intervals inside [0, x]: those before x, and at a breakpoint x its
    left side only."""
    s = np.asarray(s)
    return (s < x - 1e-12) | ((np.abs(s - x) <= 1e-12) & ~_starts(s))


def _tube_mask(s, insertion):
    """True at the nodes inside the tube, [0, d]."""
    return _upto(s, insertion) if insertion > 0 else np.zeros(np.shape(s), bool)


@_styled
def plot_shape(sol: Solution, insertion: float, path: str | Path | None = None, title: str | None = None, target=None):
    """Side view (world z-y plane) and 3D view of one solved shape; the tube part drawn thick.

    Args:
        sol: a single (unbatched) Solution.
        insertion: tube insertion depth d [m], to mark the backbone segment [0, d].
        path: where to save a PNG; the figure is returned either way.
        title: figure title.
        target: a target tip position [m], (3,), marked with a cross (inverse kinematics).
    """
    plt = _pyplot()
    p = np.asarray(sol.position) * 1e3
    tube = _tube_mask(sol.s, insertion)
    fig = plt.figure(figsize=(11, 4.6))
    ax = fig.add_subplot(1, 2, 1)
    ax.plot(p[:, 2], p[:, 1], color="tab:blue", lw=2, label="silicone only")
    if tube.any():
        ax.plot(p[tube, 2], p[tube, 1], color="black", lw=4, label=f"with Nitinol tube (d = {insertion * 1e3:.0f} mm)")
    ax.plot(*p[-1, [2, 1]], "o", color="tab:red", label="tip")
    if target is not None:
        q = np.asarray(target) * 1e3
        ax.plot(q[2], q[1], "x", color="tab:green", ms=10, mew=2, label="target")
    ax.axhline(0, color="0.8", lw=0.8, zorder=0)
    ax.set_xlabel("z [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(f"side view: tip angle {np.degrees(float(sol.tip_angle)):.1f} deg")
    ax.legend(loc="best")
    ax.grid(alpha=0.3)
    ax3 = fig.add_subplot(1, 2, 2, projection="3d")
    ax3.plot(p[:, 0], p[:, 2], p[:, 1], color="tab:blue", lw=2)
    if tube.any():
        ax3.plot(p[tube, 0], p[tube, 2], p[tube, 1], color="black", lw=4)
    ax3.scatter(*p[-1, [0, 2, 1]], color="tab:red")
    if target is not None:
        ax3.scatter(*q[[0, 2, 1]], color="tab:green", marker="x", s=80)
    _equal_3d(ax3, p if target is None else np.vstack([p, q]))
    ax3.set_title("3D (gravity along -y)")
    if title:
        fig.suptitle(title)
    return _finish(fig, path)


@_styled
def plot_robot(sol, robot, act=None, load=None, path: str | Path | None = None, title: str | None = None, target=None):
    """Side view (world z-y), top view (z-x) and 3D view of a solved ``Robot``, in mm: the
    body coloured by section, each tube's insertion shaded, every tendon along the body from the
    base to its anchor (a dot, its number beside it in 3D, in its anchor section's colour), point
    masses as disks across the body, point loads and the tip force as arrows. With a scene in the
    load: the body's outline to scale, the obstacles (a plane as its trace and its solid side in
    the flat views, a patch of it in 3D; spheres and capsules as their outlines, their surfaces in
    3D; ``Distance`` obstacles are not drawn) and each contact force on the robot as an arrow
    from the touching point, on the same scale as the loads.

    Args:
        sol: a single (unbatched) Solution of ``robot`` (with ``sol.contact`` for a scene).
        robot: the Robot solved.
        act, load: its Actuation (tube depths) and Loads (``load.scene``: the obstacles it was
            solved with); None: none.
        path: where to save a PNG; the figure is returned either way.
        title: figure title.
        target: a target tip position [m], (3,), marked with a cross (inverse kinematics).
    """
    from .inputs import Actuation, Loads

    plt = _pyplot()
    act, load = Actuation.of(act, robot), Loads.of(load)
    s, p, R = np.asarray(sol.s), np.asarray(sol.position) * 1e3, np.asarray(sol.rotation)
    length = float(robot.length)
    ends = [float(sec.end) for sec in robot.sections]
    starts = [0.0, *ends[:-1]]
    # each node's section: at a section end, its left side in the section that ends, its right side in the next
    section = np.where(_starts(s), np.searchsorted(ends, s, side="right"), np.searchsorted(ends, s - 1e-12))
    section = section.clip(0, len(ends) - 1)
    colours = [plt.cm.tab10(j % 10) for j in range(len(ends))]
    anchors = [length if t.end is None else float(t.end) for t in robot.tendons]
    at = [int(np.searchsorted(ends, a - 1e-12)) for a in anchors]  # each anchor's section
    paths = [p + 1e3 * np.einsum("nij,nj->ni", R, np.broadcast_to(t.position(s)[0], p.shape)) for t in robot.tendons]
    reach = max([float(t.offset) for t in robot.tendons] + [float(sec.outer_diameter) / 2 for sec in robot.sections])
    circle = np.linspace(0, 2 * np.pi, 41)
    ring = 1.3e3 * reach * np.stack([np.cos(circle), np.sin(circle), 0 * circle], 1)  # a disk's rim, body frame [mm]
    disks = [p[k] + ring @ R[k].T for k in (_node(s, float(m.s)) for m in robot.masses)]
    forces = [(float(x), np.asarray(f)) for x, f in zip(np.asarray(load.point_s), np.asarray(load.point_force), strict=True)]
    forces += [(length, np.asarray(load.tip_force))] if np.any(np.asarray(load.tip_force)) else []
    scene = load.scene
    radius = 1e3 * np.array([float(robot.sections[j].outer_diameter) / 2 for j in section])
    touching = _touching(sol, scene, radius, s) if scene is not None else []
    biggest = max([np.linalg.norm(f) for _, f in forces] + [np.linalg.norm(f) for _, f in touching], default=0.0)
    arrows = [(p[_node(s, x)], 0.2 * length * 1e3 * f / biggest) for x, f in forces if np.linalg.norm(f) > 0]
    pushes = [(q, 0.2 * length * 1e3 * f / biggest) for q, f in touching]
    marked = [] if target is None else [np.asarray(target, dtype=float) * 1e3]

    fig = plt.figure(figsize=(17, 5.6), layout="constrained")
    views = [fig.add_subplot(1, 3, 1), fig.add_subplot(1, 3, 2), fig.add_subplot(1, 3, 3, projection="3d")]
    for ax, cols in zip(views, ((2, 1), (2, 0), (0, 2, 1)), strict=True):
        xyz = functools.partial(_columns, cols=cols)
        for j, d in enumerate(np.asarray(act.insertions)):
            inside = _tube_mask(s, d)
            if d > 0:
                label = f"tube {j + 1} inserted {d * 1e3:g} mm"
                ax.plot(*xyz(p[inside]), color="0.3", lw=10 + 4 * j, alpha=0.25, solid_capstyle="butt", label=label)
        for j, (a, b) in enumerate(zip(starts, ends, strict=True)):
            piece = (s >= a - 1e-12) & (s <= b + 1e-12)  # at a section end both sides: the same point
            ax.plot(*xyz(p[piece]), color=colours[j], lw=3.5, label=f"section {j + 1}: {a * 1e3:g}-{b * 1e3:g} mm")
        for i, (q, a) in enumerate(zip(paths, anchors, strict=True)):
            on = _upto(s, a)
            on[0] = True
            ax.plot(*xyz(q[on]), color=colours[at[i]], lw=1.1, alpha=0.8)
            ax.plot(*xyz(q[on][-1]), "o", color=colours[at[i]], mec="black", ms=5)
            if len(cols) == 3:
                ax.text(*xyz(q[on][-1]), f" {i + 1}", fontsize="small")
        for disk in disks:
            ax.plot(*xyz(disk), color="saddlebrown", lw=2)
        for q in marked:
            ax.plot(*xyz(q[None]), "x", color="tab:green", ms=10, mew=2)
        for (base, vec), colour in [*((a, "tab:red") for a in arrows), *((a, "tab:green") for a in pushes)]:
            if len(cols) == 3:
                ax.quiver(*xyz(base), *xyz(vec), color=colour, lw=2, arrow_length_ratio=0.2)
            else:
                ax.annotate("", xy=xyz(base + vec), xytext=xyz(base), arrowprops=dict(arrowstyle="->", color=colour, lw=2))
        if scene is not None and len(cols) == 2:
            _outline(ax, p[:, cols], radius)
            _draw_scene(ax, scene, cols, p)
        elif scene is not None:
            _draw_scene_3d(ax, scene, p)
    side, top, ax3 = views
    if robot.tendons:
        side.plot([], [], "-o", color="0.4", lw=1.1, ms=5, mec="black", label="tendons, to their anchors (numbered in 3D)")
    if disks:
        side.plot([], [], color="saddlebrown", lw=2, label="point masses")
    if arrows:
        side.plot([], [], color="tab:red", lw=2, label=f"forces: point loads, tip (longest {biggest:.3g} N)")
    if scene is not None:
        side.fill([], [], color=OBSTACLE, alpha=0.35, label=f"obstacles: {', '.join(scene.names)}")
        if pushes:
            largest = max(np.linalg.norm(f) for _, f in touching)
            side.plot([], [], color="tab:green", lw=2, label=f"contact forces on the robot (largest {largest:.3g} N)")
    if marked:
        side.plot([], [], "x", color="tab:green", ms=10, mew=2, label="target")
    every = np.concatenate([p, *paths, *disks, *(np.stack([b, b + v]) for b, v in arrows + pushes), *(q[None] for q in marked)])
    if scene is not None:
        every = np.concatenate([every, _scene_points(scene, p)])
    for ax, (h, v), name in ((side, (2, 1), "side view"), (top, (2, 0), "top view")):
        ax.set_xlabel(f"{'xyz'[h]} [mm]")
        ax.set_ylabel(f"{'xyz'[v]} [mm]")
        ax.update_datalim(every[:, [h, v]])
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(name)
    side.set_title(f"side view: tip angle {np.degrees(float(sol.tip_angle)):.1f} deg")
    _equal_3d(ax3, every)
    ax3.set_title("3D (gravity along -y)")
    fig.legend(*side.get_legend_handles_labels(), loc="outside lower center", ncols=4, fontsize="small")
    if title:
        fig.suptitle(title)
    return _finish(fig, path)


OBSTACLE = "0.5"
"""The obstacles' colour."""


def _touching(sol, scene, radius, s) -> list:
    """(touching point on the body's surface [mm], force on the robot [N]) of each active contact:
    the centreline point less the body's radius along the obstacle's normal."""
    c = sol.contact
    out = []
    for j, o in zip(*np.nonzero(np.asarray(c.active)), strict=True):
        n = np.asarray(c.normal)[j, o]
        out.append((1e3 * np.asarray(c.position)[j] - radius[_node(s, float(c.s[j]))] * n, float(c.force[j, o]) * n))
    return out


def _outline(ax, q, radius):
    """The body's silhouette in a flat view: the centreline q (n, 2) [mm] offset by the radius
    (n,) [mm] to both sides of its tangent."""
    if len(q) < 2:
        return
    distinct = np.r_[True, np.any(np.diff(q, axis=0) != 0, axis=1)]  # the nodes on both sides of a breakpoint: once
    if distinct.sum() < 2:
        return
    t = np.gradient(q[distinct], axis=0)[np.cumsum(distinct) - 1]
    t = t / np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)
    side = np.stack([-t[:, 1], t[:, 0]], 1) * radius[:, None]
    for sign in (1, -1):
        ax.plot(*(q + sign * side).T, color="0.25", lw=0.8)


def _draw_scene(ax, scene, cols, p):
    """The obstacles in the flat view of world columns ``cols`` (h, v), in mm. A sphere or capsule
    is drawn as its projection; a plane as its trace in the view's plane through the robot's mean
    depth, its solid side shaded (not drawn when the view looks along it)."""
    from matplotlib.patches import Polygon

    from .scene import Capsule, Plane, Sphere

    depth_col = 3 - sum(cols)
    depth = p[:, depth_col].mean()
    for o, name in zip(scene.obstacles, scene.names, strict=True):
        if isinstance(o, Plane):
            n, point = np.asarray(o.normal), 1e3 * np.asarray(o.point)
            n2 = n[list(cols)]
            if np.linalg.norm(n2) < 0.05:
                continue
            c = n @ point - n[depth_col] * depth
            x0 = c * n2 / (n2 @ n2)
            t, inward = np.array([-n2[1], n2[0]]) / np.linalg.norm(n2), -n2 / np.linalg.norm(n2)
            far = 1e5
            solid = [x0 + far * t, x0 - far * t, x0 - far * t + far * inward, x0 + far * t + far * inward]
            ax.add_artist(Polygon(solid, closed=True, color=OBSTACLE, alpha=0.25, lw=0))  # add_artist: the limits ignore it
            ax.axline(x0, x0 + t, color=OBSTACLE, lw=1.5)
            label = _foot(p[:, list(cols)].mean(0), n2, c) + 0.05 * np.ptp(p, axis=0).max() * inward
        elif isinstance(o, (Sphere, Capsule)):
            a, b = (o.center, o.center) if isinstance(o, Sphere) else (o.a, o.b)
            outline = _stadium(1e3 * np.asarray(a)[list(cols)], 1e3 * np.asarray(b)[list(cols)], 1e3 * float(o.radius))
            ax.add_patch(Polygon(outline, closed=True, facecolor=OBSTACLE, edgecolor=OBSTACLE, alpha=0.35, lw=1.5))
            label = outline.mean(0)
        else:
            continue
        ax.text(*label, name, fontsize="small", ha="center", va="center")


def _foot(q, n2, c):
    """The foot of the point q (2,) on the line n2 . x = c."""
    return q - (n2 @ q - c) / (n2 @ n2) * n2


def _stadium(a, b, r, k=24):
    """The outline (2 k, 2) of the points within r of the segment [a, b] in a plane (a = b: a circle)."""
    d = b - a
    angle = np.arctan2(d[1], d[0]) if np.linalg.norm(d) > 0 else 0.0
    half = np.linspace(-np.pi / 2, np.pi / 2, k)
    arc = lambda centre, phi: centre + r * np.stack([np.cos(phi), np.sin(phi)], 1)  # noqa: E731
    return np.concatenate([arc(b, angle + half), arc(a, angle + np.pi + half)])


def _draw_scene_3d(ax3, scene, p):
    """The obstacles in the 3D view (drawn as x, z, y), in mm: a square of each plane around the
    foot of the robot's centre, each sphere's and capsule's surface."""
    from .scene import Capsule, Plane, Sphere

    size = max(np.ptp(p, axis=0).max(), 1.0)
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 25), np.linspace(0, np.pi, 13))
    ball = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)], -1)
    for o in scene.obstacles:
        if isinstance(o, Plane):
            n = np.asarray(o.normal)
            centre = p.mean(0) - (n @ (p.mean(0) - 1e3 * np.asarray(o.point))) * n
            e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(n, e1)
            g = np.linspace(-0.6, 0.6, 2) * size
            surface = centre + g[:, None, None] * e1 + g[None, :, None] * e2
        elif isinstance(o, (Sphere, Capsule)):
            a, b = (o.center, o.center) if isinstance(o, Sphere) else (o.a, o.b)
            a, b, r = 1e3 * np.asarray(a), 1e3 * np.asarray(b), 1e3 * float(o.radius)
            # a sphere swept along [a, b]: the upper half sphere at b, the lower at a
            shift = np.where(ball @ (b - a)[:, None] >= 0, b, a) if np.any(b != a) else a
            surface = shift + r * ball
            if np.any(b != a):
                ax3.plot_surface(*_cylinder(a, b, r)[..., [0, 2, 1]].transpose(2, 0, 1), color=OBSTACLE, alpha=0.3, lw=0)
        else:
            continue
        ax3.plot_surface(*surface[..., [0, 2, 1]].transpose(2, 0, 1), color=OBSTACLE, alpha=0.3, lw=0)


def _cylinder(a, b, r):
    """The surface (2, 25, 3) of the cylinder of radius r about [a, b]."""
    d = (b - a) / np.linalg.norm(b - a)
    e1 = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    phi = np.linspace(0, 2 * np.pi, 25)[None, :, None]
    ring = r * (np.cos(phi) * e1 + np.sin(phi) * e2)
    return np.stack([a, b])[:, None, :] + ring


def _scene_points(scene, p):
    """Points [mm] the views must show besides the robot: each plane's point nearest the tip and
    nearest the robot's centre (its name goes there, a little inside), each sphere's and
    capsule's extent."""
    from .scene import Capsule, Plane, Sphere

    points, inside = [], 0.1 * np.ptp(p, axis=0).max()
    for o in scene.obstacles:
        if isinstance(o, Plane):
            n, q = np.asarray(o.normal), 1e3 * np.asarray(o.point)
            points += [x - (n @ (x - q)) * n for x in (p[-1], p.mean(0))]
            points.append(points[-1] - inside * n)
        elif isinstance(o, (Sphere, Capsule)):
            ends = [o.center] if isinstance(o, Sphere) else [o.a, o.b]
            r = 1e3 * float(o.radius)
            points += [1e3 * np.asarray(e) + sign * r for e in ends for sign in (-1, 1)]
    return np.reshape(points, (-1, 3))


def _columns(q, cols):
    """The coordinates ``cols`` of points q (..., 3), as a list of arrays (one per plot axis)."""
    return [q[..., c] for c in cols]


def _node(s, x) -> int:
    """The node nearest arc length x (breakpoints are nodes)."""
    return int(np.argmin(np.abs(s - x)))


def _equal_3d(ax3, p):
    """Labels a 3D axes drawn as (x, z, y) [mm] and gives it equal spans around the points (k, 3)."""
    ax3.set_xlabel("x [mm]")
    ax3.set_ylabel("z [mm]")
    ax3.set_zlabel("y [mm]")
    span = max(np.ptp(p, axis=0).max(), 1.0) / 2
    mid = (p.max(0) + p.min(0)) / 2
    ax3.set_xlim(mid[0] - span, mid[0] + span)
    ax3.set_ylim(mid[2] - span, mid[2] + span)
    ax3.set_zlim(mid[1] - span, mid[1] + span)


@_styled
def plot_calibration(solutions: Solution, experiments, path: str | Path | None = None, title: str | None = None):
    """Model shapes (lines) over measured shapes (markers), like the paper's Figs. 6 and 7.

    Left: side view in the world z-y plane (Fig. 6); right: 3D (Fig. 7). The legend gives each
    experiment's RMSE (eq. 39) and tip error.

    Args:
        solutions: the model's Solutions, batched with a leading axis (one per experiment).
        experiments: the measured shapes (a list of ``data.Experiment``), in the same order.
        path: where to save a PNG; the figure is returned either way.
        title: figure title.
    """
    from .mechanics import shape_errors

    plt = _pyplot()
    fig = plt.figure(figsize=(12, 5))
    ax = fig.add_subplot(1, 2, 1)
    ax3 = fig.add_subplot(1, 2, 2, projection="3d")
    colors = plt.cm.viridis(np.linspace(0.0, 0.9, len(experiments)))
    every = []
    for i, (e, c) in enumerate(zip(experiments, colors, strict=True)):
        sol = jax.tree.map(lambda a, i=i: a[i], solutions)
        p, q = np.asarray(sol.position) * 1e3, np.asarray(e.position) * 1e3
        _, e_rms, e_tip = shape_errors(sol, e)
        label = f"{e.name}: RMSE {float(e_rms) * 1e3:.2f} mm, tip {float(e_tip) * 1e3:.2f} mm"
        ax.plot(p[:, 2], p[:, 1], color=c, lw=1.8, label=label)
        ax.plot(q[:, 2], q[:, 1], "o", mfc="none", color=c, ms=4)
        ax3.plot(p[:, 0], p[:, 2], p[:, 1], color=c, lw=1.8)
        ax3.scatter(q[:, 0], q[:, 2], q[:, 1], color=c, s=8)
        every += [p, q]
    ax.plot([], [], "o", mfc="none", color="0.3", ms=4, label="measured")
    ax.plot([], [], color="0.3", lw=1.8, label="model")
    ax.axhline(0, color="0.8", lw=0.8, zorder=0)
    ax.set_xlabel("z [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title("side view (paper Fig. 6)")
    ax.legend(loc="best")
    ax.grid(alpha=0.3)
    _equal_3d(ax3, np.concatenate(every))
    ax3.set_title("3D (paper Fig. 7)")
    if title:
        fig.suptitle(title)
    return _finish(fig, path)


@_styled
def plot_fd_error(rows, path: str | Path):
    """Relative error of finite-difference compliance against the exact one vs the FD step (V curve).

    Args:
        rows: dicts with keys config, fd_steps_N, fd_relative_error (benchmarks/compliance_autodiff_vs_fd.py).
        path: PNG to write.
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for row in rows:
        ax.loglog(row["fd_steps_N"], row["fd_relative_error"], "o-", label=row["config"])
    ax.set_xlabel("finite-difference step in tip force [N]")
    ax.set_ylabel("relative error of FD compliance vs exact")
    ax.set_title("Central differences against the exact (autodiff) CM")
    ax.grid(alpha=0.3, which="both")
    ax.legend()
    _finish(fig, path)


@_styled
def plot_compliance_ellipses(
    CMs: dict, path: str | Path | None = None, title: str | None = None, legend_title: str | None = None
):
    """Compliance ellipsoids {CM f : |f| = 1} projected on the plane of the first one's two largest
    axes, mu_3 and mu_2 (paper Fig. 10), in mm/N; a note gives the third, lambda_1, left out.

    Args:
        CMs: label -> 3x3 compliance matrix [m/N]; the first sets the projection plane.
        path: where to save a PNG; the figure is returned either way.
        title: axes title.
        legend_title: the legend's title (the legend sits inside the innermost ellipse).
    """
    plt = _pyplot()
    mats = {k: np.asarray(v) * 1e3 for k, v in CMs.items()}
    U, _, _ = np.linalg.svd(next(iter(mats.values())))
    plane = U[:, :2]
    t = np.linspace(0, 2 * np.pi, 200)
    fig, ax = plt.subplots(figsize=(6.4, 6.4))
    for label, CM in mats.items():
        u, s, _ = np.linalg.svd(plane.T @ CM)
        xy = u @ (s[:, None] * np.stack([np.cos(t), np.sin(t)]))
        ax.plot(xy[0], xy[1], lw=2.2, label=label)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(r"along the major axis $\mu_3$ [mm/N]")
    ax.set_ylabel(r"along $\mu_2$ [mm/N]")
    ax.set_title(title or "compliance ellipse (tip displacement per N of tip force)")
    ax.legend(loc="center", title=legend_title, frameon=False, handlelength=1.2, borderaxespad=0)
    smallest = max(np.linalg.svd(CM, compute_uv=False)[-1] for CM in mats.values())
    note = rf"left out: $\lambda_1$ (along $\mu_1$, near the tip's tangent), at most {smallest:.2g} mm/N"
    fig.text(0.5, 0.01, note, ha="center", va="bottom", fontsize="medium", color="0.3")
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    return _finish(fig, path)


@_styled
def plot_fig11(tensions, insertions, lam, path: str | Path | None = None):
    """Paper Fig. 11: lambda_1..3 of CM [mm/N] against insertion depth [mm], one colour per tension."""
    plt = _pyplot()
    d_mm = np.asarray(insertions) * 1e3
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.6))
    colours = plt.cm.viridis(np.linspace(0, 0.9, len(tensions)))
    for k, ax in enumerate(axes):
        for tau, c, row in zip(tensions, colours, np.asarray(lam), strict=True):
            ax.plot(d_mm, row[:, k] * 1e3, "o-", ms=3.5, color=c, label=f"{tau:g} N")
        ax.set_xlabel(LABEL["insertion"])
        ax.set_ylabel(rf"$\lambda_{k + 1}$ [mm/N]")
    axes[0].legend(title="tendon 1 tension")
    fig.suptitle("Eigenvalues of the tip compliance matrix (paper Fig. 11)")
    return _finish(fig, path)


@_styled
def plot_fig8a(res, path: str | Path | None = None):
    """Paper Fig. 8A: side views of the shape as the tube goes in; arrow: the tip's motion.

    Args:
        res: SweepResult of ``paper.fig8a_shapes`` (shapes=True; insertion axis first).
    """
    plt = _pyplot()
    depths = np.asarray(res.axes["insertion"])
    tension = float(np.asarray(res.axes["tensions"])[0, 0])
    fig, ax = plt.subplots(figsize=(8.5, 5.8))
    colours = plt.cm.plasma(np.linspace(0, 0.85, len(depths)))
    for i, (d, c) in enumerate(zip(depths, colours, strict=True)):
        p = res.position[i, 0] * 1e3
        tube = _tube_mask(res.s[i, 0], d)
        ax.plot(p[:, 2], p[:, 1], color=c, lw=2, zorder=3, label=f"$d$ = {d * 1e3:.0f} mm")
        if tube.any():
            ax.plot(p[tube, 2], p[tube, 1], color="black", lw=6, zorder=2, solid_capstyle="butt")
            ax.plot(*p[tube][-1, [2, 1]], "o", mfc="white", mec="black", ms=6, zorder=4)
    ax.plot([], [], color="black", lw=6, label="inside the tube")
    ax.plot([], [], "o", mfc="white", mec="black", ms=6, label="tube end ($s = d$)")
    tips = res.tip_position[:, 0] * 1e3
    ax.annotate("", xy=tips[-1, [2, 1]], xytext=tips[0, [2, 1]], arrowprops=dict(arrowstyle="->", color="red", lw=2))
    ax.axhline(0, color="0.8", lw=0.8, zorder=0)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(LABEL["z"])
    ax.set_ylabel(LABEL["y"])
    ax.set_title(f"Shape as the tube goes in: {tension:g} N on tendon 1, no tip load (paper Fig. 8A)")
    ax.legend(loc="upper left")
    return _finish(fig, path)


@_styled
def plot_fig8b(res, path: str | Path | None = None):
    """Paper Fig. 8B: the tip workspace of tendon 1 alone (a curve, d = 0) and with the insertion
    (a band: every tension and insertion of the grid), in the z-y plane at equal scales.

    Args:
        res: SweepResult of ``paper.tip_pose_grid`` (tension axis first, insertion second).
    """
    from matplotlib.collections import PolyCollection

    plt = _pyplot()
    tip = res.tip_position[..., [2, 1]] * 1e3  # (tension, insertion, (z, y))
    depths = np.asarray(res.axes["insertion"]) * 1e3
    taus = np.asarray(res.axes["tensions"])[:, 0]
    fig, ax = plt.subplots(figsize=(6.6, 7.8))
    cells = np.stack([tip[:-1, :-1], tip[1:, :-1], tip[1:, 1:], tip[:-1, 1:]], axis=2).reshape(-1, 4, 2)
    band = "#74add1"
    ax.add_collection(PolyCollection(cells, facecolors=band, edgecolors=band, linewidths=0.6, zorder=1))
    ax.fill([], [], color=band, label=f"tendon 1 and the tube,\n$d$ = {depths[0]:g}-{depths[-1]:g} mm")
    ax.plot(tip[:, -1, 0], tip[:, -1, 1], "-", color="navy", lw=1.2, zorder=2, label=f"$d$ = {depths[-1]:g} mm")
    ax.plot(tip[:, 0, 0], tip[:, 0, 1], "o-", color="black", lw=1.5, ms=3.5, zorder=3, label="tendon 1 alone ($d$ = 0)")
    for i in sorted({0, len(taus) // 2, len(taus) - 1}):
        ax.annotate(f"{taus[i]:g} N", tip[i, 0], xytext=(10, 0), textcoords="offset points", ha="left", va="center")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(LABEL["z_tip"])
    ax.set_ylabel(LABEL["y_tip"])
    ax.set_title(f"Tip workspace (paper Fig. 8B): tendon 1 at {taus[0]:g}-{taus[-1]:g} N")
    ax.legend(loc="center left", fontsize="small")
    return _finish(fig, path)


@_styled
def plot_fig9(res, path: str | Path | None = None):
    """Paper Fig. 9A-C: z_tip, y_tip [mm] and theta_tip [deg] against insertion, one line per tension."""
    plt = _pyplot()
    depths = np.asarray(res.axes["insertion"]) * 1e3
    taus = np.asarray(res.axes["tensions"])[:, 0]
    values = (res.tip_position[..., 2] * 1e3, res.tip_position[..., 1] * 1e3, np.degrees(res.tip_angle))
    labels = (LABEL["z_tip"], LABEL["y_tip"], LABEL["theta_tip"])
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.8))
    colours = plt.cm.viridis(np.linspace(0, 0.95, len(taus)))
    for ax, v, label, letter in zip(axes, values, labels, "ABC", strict=True):
        for tau, c, row in zip(taus, colours, v, strict=True):
            ax.plot(depths, row, "o-", ms=3, color=c, label=f"{tau:g} N")
        ax.set_xlabel(LABEL["insertion"])
        ax.set_ylabel(label)
        ax.set_title(f"({letter})")
    axes[2].legend(title="tendon 1\ntension", loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize="small")
    fig.suptitle("Tip pose against tube insertion, no tip load (paper Fig. 9)")
    return _finish(fig, path)


@_styled
def plot_fig13(results: dict, path: str | Path | None = None):
    """Paper Fig. 13: y_tip [mm] against insertion [mm] for several tip masses, optimum as a black dot.

    Args:
        results: {tension [N]: GridResult of ``paper.fig13_optima``}, one panel each.
    """
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(results), figsize=(6.6 * len(results) + 1.6, 5.0), squeeze=False)
    all_masses = [np.asarray(r.axes["tip_mass"]).tolist() for r in results.values()]
    shared = all(m == all_masses[0] for m in all_masses)  # then one legend serves every panel
    for k, (ax, (tension, r), letter) in enumerate(zip(axes[0], results.items(), "ABCD", strict=False)):
        masses = np.asarray(r.axes["tip_mass"]) * 1e3
        colours = plt.cm.cividis(np.linspace(0, 0.9, len(masses)))
        for i, (m, c) in enumerate(zip(masses, colours, strict=True)):
            ax.plot(r.curve_insertion * 1e3, r.curve_height[i] * 1e3, "-", lw=2, color=c, label=f"{m:g} g")
            ax.plot(r.insertion[i] * 1e3, r.height[i] * 1e3, "o", color="black", ms=6)
        ax.plot([], [], "o", color="black", ms=6, label=r"maximum of $y_{\mathrm{tip}}$")
        ax.set_xlabel(LABEL["insertion"])
        ax.set_ylabel(LABEL["y_tip"])
        ax.set_title(f"({letter}) tendon 1 at {tension:g} N")
        if not shared or k == len(results) - 1:
            ax.legend(title="tip mass", loc="upper left", bbox_to_anchor=(1.02, 1.0))
    fig.suptitle("Tip height against insertion for several tip masses (paper Fig. 13)")
    return _finish(fig, path)


@_styled
def plot_fig14(res, paper_points=None, path: str | Path | None = None):
    """Paper Fig. 14: load capacity [g] against insertion [mm], one line per tension.

    Args:
        res: GridResult of ``paper.fig14_capacities`` (tension axis first, insertion second).
        paper_points: optional (insertions [m], capacities [g] with one row per insertion and one
            column per tension), drawn as crosses.
    """
    plt = _pyplot()
    depths = np.asarray(res.axes["insertion"]) * 1e3
    taus = np.asarray(res.axes["tensions"])[:, 0]
    fig, ax = plt.subplots(figsize=(9.2, 5.4))
    colours = plt.cm.viridis(np.linspace(0, 0.9, len(taus)))
    for i, (tau, c) in enumerate(zip(taus, colours, strict=True)):
        ax.plot(depths, res.mass[i] * 1e3, "o-", ms=3.5, color=c, label=f"{tau:g} N")
        if paper_points is not None:
            d, g = paper_points
            ax.plot(np.asarray(d) * 1e3, np.asarray(g)[:, i], "x", color=c, ms=10, mew=2.2)
    if paper_points is not None:
        ax.plot([], [], "x", color="black", ms=10, mew=2.2, label="paper (Sec. V.A)")
    ax.set_xlabel(LABEL["insertion"])
    ax.set_ylabel(r"load capacity [g] (tip at $y = 0$)")
    ax.set_title("Tip load capacity against insertion (paper Fig. 14)")
    ax.legend(title="tendon 1 tension", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return _finish(fig, path)


@_styled
def plot_tip_angle_family(family, path: str | Path | None = None):
    """Sec. V.B: tip angle against insertion at fixed tip heights (left), and at each height (the
    few that were solved: markers, not a continuum) the range of angles the tube allows against
    the single angle of the tendon-only robot (right); both share the tip-angle axis."""
    plt = _pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12.5, 5.0), sharey=True, gridspec_kw=dict(width_ratios=(3, 2)))
    colors = plt.cm.viridis(np.linspace(0, 0.9, len(family.heights)))
    d_mm = family.insertions * 1e3
    y_mm = family.heights * 1e3
    for k, (h, c) in enumerate(zip(y_mm, colors, strict=True)):
        ok = family.reached[k]
        angle = np.degrees(np.where(ok, family.tip_angle[k], np.nan))
        ax.plot(d_mm, angle, "o-", color=c, ms=3.5, label=f"{h:g} mm")
        if not ok.any():
            continue
        lo, hi = np.nanmin(angle), np.nanmax(angle)
        bx.plot([h, h], [lo, hi], "-", color=c, lw=7, alpha=0.45, solid_capstyle="butt")
        bx.plot([h, h], [lo, hi], "_", color=c, ms=22, mew=2)
        bx.annotate(f"{hi - lo:.1f}°", (h, hi), xytext=(0, 8), textcoords="offset points", ha="center")
        if ok[0]:
            bx.plot(h, angle[0], "ks", ms=8, zorder=3)
    ax.set(xlabel="tube insertion $d$ [mm]", ylabel=LABEL["theta_tip"], title="tip held at a height, tendon 1 re-solved")
    ax.legend(title=r"tip height $y_{\mathrm{tip}}$", loc="upper right", fontsize="small")
    bx.plot([], [], "-", color="0.5", lw=7, alpha=0.45, label="range with the tube")
    bx.plot([], [], "ks", ms=8, label="tendon 1 alone ($d$ = 0)")
    bx.set(xlabel=r"tip height $y_{\mathrm{tip}}$ [mm]", title="tip angles at each height")
    bx.set_xticks(y_mm)
    span = max(np.ptp(y_mm), 1.0)
    bx.set_xlim(y_mm.min() - 0.15 * span, y_mm.max() + 0.15 * span)
    bx.tick_params(labelleft=True)
    bx.legend(loc="lower right")
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi + 0.08 * (hi - lo))  # room for the ranges' labels above the highest
    fig.suptitle("Sec. V.B: the tube insertion as a redundant input for the tip angle")
    return _finish(fig, path)


@_styled
def plot_stiffest_reach(reach, top=None, path: str | Path | None = None):
    """Sec. V.A: the stiffest actuation for each target height (left: insertion, bottom axis;
    tendon-1 tension, top axis) and its compliance along -y against the tendon-only actuation's
    (right). ``top``: the highest reach (``paper.HighestReach``), where each curve ends, marked."""
    plt = _pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 6.2), sharey=True, layout="constrained")
    heights, insertion, tension, comp = reach.heights, reach.insertion, reach.tension, reach.compliance
    ok = reach.reached
    if top is not None:
        heights, ok = np.append(heights, top.height), np.append(ok, top.converged)
        insertion, tension = np.append(insertion, top.insertion), np.append(tension, top.tension)
        comp = np.append(comp, top.compliance)
    y_mm = heights * 1e3
    handles = ax.plot(
        np.where(ok, insertion * 1e3, np.nan), y_mm, "o-", color="tab:blue", label="stiffest: insertion (bottom axis)"
    )
    tx = ax.twiny()
    handles += tx.plot(np.where(ok, tension, np.nan), y_mm, "s--", color="tab:orange", ms=5, label="stiffest: tension (top axis)")
    tx.set_xlabel("tendon 1 tension [N]", color="tab:orange")
    tx.tick_params(axis="x", colors="tab:orange")
    tx.set_xlim(-0.5, (10.0 if top is None else top.tension_bound) + 0.6)
    tx.grid(False)
    handles += bx.plot(comp * 1e3, y_mm, "o-", color="tab:green", label="stiffest: compliance (right)")
    only = reach.tendon_only_compliance * 1e3
    handles += bx.plot(only, reach.heights * 1e3, "s-", color="0.3", label="tendon 1 alone ($d$ = 0): compliance")
    if top is not None:
        label = f"highest reach: $d$ = {top.insertion * 1e3:.1f} mm at {top.tension:g} N"
        handles += ax.plot(top.insertion * 1e3, top.height * 1e3, "*", color="red", ms=18, zorder=5, label=label)
        bx.plot(top.compliance * 1e3, top.height * 1e3, "*", color="red", ms=18, zorder=5)
    handles.append(ax.axvline(70, color="0.4", ls=":", lw=1.5, label="paper: 70 mm (read off a 10 mm grid)"))
    ax.set(xlabel="tube insertion $d$ [mm]", ylabel=LABEL["target_height"])
    bx.set(xlabel=LABEL["compliance_down"], title="what the tube buys in stiffness")
    bx.tick_params(labelleft=True)
    fig.legend(handles=handles, loc="outside lower center", ncols=3, fontsize="small")
    fig.suptitle(f"Sec. V.A: {reach.mass * 1e3:g} g at the tip, each height reached the stiffest way, up to the highest reach")
    return _finish(fig, path)


@_styled
def plot_stiffness_map(stiffness, path: str | Path | None = None):
    """Over in-plane targets (tendons 1 and 3 with the tube): the tip compliance along -y of the
    least-tension and the stiffest solution (left) and how much lower the stiffest is [%] (right),
    against the target's height; one colour scale, the insertion the stiffest solution chooses."""
    plt = _pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13.5, 5.2), sharex=True, layout="constrained")
    y = stiffness.y.ravel() * 1e3
    least, stiff = stiffness.least_tension.ravel() * 1e3, stiffness.stiffest.ravel() * 1e3
    gain = 100 * (1 - stiff / least)
    depth = stiffness.insertion_stiffest.ravel() * 1e3
    ok = np.isfinite(gain)
    scale = dict(c=depth[ok], cmap="viridis", vmin=0.0, vmax=np.nanmax(depth) if ok.any() else 1.0, s=45, zorder=3)
    ax.scatter(y[ok], least[ok], marker="o", facecolors="none", edgecolors="0.45", s=45, label="least tension")
    ax.scatter(y[ok], stiff[ok], marker="o", edgecolors="none", label="stiffest", **scale)
    im = bx.scatter(y[ok], gain[ok], marker="o", edgecolors="none", **scale)
    ax.set(xlabel=LABEL["target_height"], ylabel=LABEL["compliance_down"], title="compliance of the two choices")
    bx.set(xlabel=LABEL["target_height"], ylabel="stiffest: compliance lower by [%]", title="what choosing for stiffness buys")
    ax.legend(loc="best")
    if not ok.all():
        bx.text(0.02, 0.02, f"{(~ok).sum()} targets not reached by both", transform=bx.transAxes)
    fig.colorbar(im, ax=[ax, bx], label="insertion the stiffest solution chooses [mm]", pad=0.02)
    fig.suptitle("Tendons 1 and 3 with the tube, in-plane targets: what the redundant input buys in stiffness")
    return _finish(fig, path)


@_styled
def plot_prediction(prediction, calibration=None, path: str | Path | None = None, title: str | None = None, bound=None):
    """A held-out recording predicted (``calibrate_rig.predict``): per motion-pattern family, the
    measured tip path (dots) and the model's (line) seen along the measurement frame's z (x-y, mm);
    below, the error along the sequence (mean offset removed), and with ``calibration`` the tip
    RMSE after each fit step. ``bound``: the RMSE no model without memory goes below [m] (half the
    distance between samples with equal servo values), drawn as a line. Samples that did not solve
    (``codes``) are gaps."""
    plt = _pyplot()
    families = list(prediction.per_pattern)
    fig = plt.figure(figsize=(4.2 * max(len(families), 2), 8.2))
    grid = fig.add_gridspec(2, max(len(families), 2) * 2)
    fam = prediction.families
    solved = (np.asarray(prediction.codes) == 0)[:, None]
    tips = 1e3 * np.where(solved, prediction.tips + prediction.errors["offset"], np.nan)
    measured = 1e3 * prediction.measured
    for k, f in enumerate(families):
        ax = fig.add_subplot(grid[0, 2 * k : 2 * k + 2])
        pats = list(dict.fromkeys(prediction.patterns[fam == f]))
        colors = plt.cm.viridis(np.linspace(0.0, 0.9, len(pats)))
        for p, c in zip(pats, colors, strict=True):
            m = prediction.patterns == p
            ax.plot(measured[m, 0], measured[m, 1], "o", ms=2.5, color=c, alpha=0.6)
            ax.plot(tips[m, 0], tips[m, 1], "-", lw=1.4, color=c, label=p)
        e = prediction.per_pattern[f]
        ax.set_title(f"{f}: RMSE {1e3 * e['rmse']:.1f} mm, median {1e3 * e['median']:.1f} mm", fontsize=10)
        ax.set_xlabel("tip x [mm]")
        ax.set_ylabel("tip y [mm]")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=6, loc="best")
    wide = 2 * max(len(families), 2) - (2 if calibration is not None else 0)
    ax = fig.add_subplot(grid[1, :wide])
    err = np.linalg.norm(tips - measured, axis=1)
    ax.plot(err, lw=1.0, color="C0", label=f"model (RMSE {1e3 * prediction.errors['rmse']:.2f} mm)")
    if bound is not None:
        ax.axhline(1e3 * bound, color="C3", ls="--", lw=1.0, label=f"bound without memory {1e3 * bound:.1f} mm RMS")
    starts = np.flatnonzero(np.r_[True, fam[1:] != fam[:-1]])
    for s in starts:
        ax.axvline(s, color="0.6", lw=0.6)
        ax.text(s, ax.get_ylim()[1], f" {fam[s]}", fontsize=7, va="top")
    ax.set_xlabel("sample")
    ax.set_ylabel("tip error [mm]")
    ax.legend(fontsize=8, loc="upper right")
    if calibration is not None:
        ax = fig.add_subplot(grid[1, wide:])
        ax.plot(1e3 * np.asarray(calibration.history), "o-", ms=3)
        ax.set_xlabel("fit step")
        ax.set_ylabel("training tip RMSE [mm]")
        ax.set_title(f"fit of {len(calibration.params)} values", fontsize=10)
    if title:
        fig.suptitle(title)
    return _finish(fig, path)


@_styled
def plot_pairs(predicted, measured, pairs, path: str | Path | None = None, title: str | None = None):
    """Samples with equal servo values (``calibrate_rig.equal_servo_pairs``): each pair's measured
    tip difference against the model's, component by component (mm), and their sizes. A model
    without memory predicts one tip for both samples: its points lie on the horizontal axis."""
    from .calibrate_rig import pair_score

    plt = _pyplot()
    predicted, measured = 1e3 * np.asarray(predicted), 1e3 * np.asarray(measured)
    d_m = measured[pairs[:, 1]] - measured[pairs[:, 0]]
    d_p = predicted[pairs[:, 1]] - predicted[pairs[:, 0]]
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4.2))
    for k, (axis, colour) in enumerate(zip("xyz", ("C0", "C2", "C1"), strict=True)):
        ax.plot(d_m[:, k], d_p[:, k], "o", ms=3, color=colour, alpha=0.7, label=axis)
    lim = np.abs(d_m).max() * 1.05
    ax.plot([-lim, lim], [-lim, lim], "k--", lw=0.8, label="predicted = measured")
    ax.set_xlabel("measured tip difference [mm]")
    ax.set_ylabel("predicted tip difference [mm]")
    ax.set_aspect("equal")
    ax.legend(fontsize=8)
    score = pair_score(predicted, measured, pairs)
    ax.set_title(f"{len(pairs)} equal-servo pairs: share predicted {score:.2f}", fontsize=10)
    sizes = np.linalg.norm(d_m, axis=1), np.linalg.norm(d_p, axis=1)
    bins = np.linspace(0.0, max(s.max() for s in sizes) * 1.05, 31)
    bx.hist(sizes[0], bins=bins, alpha=0.6, label="measured")
    bx.hist(sizes[1], bins=bins, alpha=0.6, label="predicted")
    bx.set_xlabel("tip distance within a pair [mm]")
    bx.set_ylabel("pairs")
    bx.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    return _finish(fig, path)


@_styled
def plot_hysteresis(loops, path: str | Path | None = None, title: str | None = None):
    """Pull-release loops, one panel each: the tip's travel along its main direction of motion
    against the pulled tendon's servo reading (mm), measured and as each model predicts it, each
    relative to its own first sample. ``loops``: dicts with ``label``, ``servo`` (n,) [m],
    ``measured`` (n, 3) [m] and ``predicted`` {model: tips (n, 3) [m]}. A model without memory
    retraces its path on the release; friction with memory opens a loop."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(loops), figsize=(4.2 * len(loops), 4), squeeze=False)
    for ax, loop in zip(axes[0], loops, strict=True):
        servo, measured = 1e3 * np.asarray(loop["servo"]), 1e3 * np.asarray(loop["measured"])
        d = measured - measured[0]
        axis = np.linalg.svd(d - d.mean(0), full_matrices=False)[2][0]
        axis = axis if d[np.argmax(np.abs(d @ axis))] @ axis > 0 else -axis
        ax.plot(servo, d @ axis, "k.-", ms=4, lw=0.8, label="measured")
        for k, (label, tips) in enumerate(loop["predicted"].items()):
            t = 1e3 * np.asarray(tips)
            ax.plot(servo, (t - t[0]) @ axis, "-", color=f"C{k}", lw=1.5, label=label)
        ax.set_xlabel("pulled tendon's servo reading [mm]")
        ax.set_title(loop["label"], fontsize=10)
    axes[0, 0].set_ylabel("tip travel along its main direction [mm]")
    axes[0, 0].legend(fontsize=8)
    if title:
        fig.suptitle(title)
    return _finish(fig, path)


@_styled
def plot_residuals(measured, predicted: dict, path: str | Path | None = None, title: str | None = None):
    """Tip errors along a recording (mean offset removed, mm), one line per model (``predicted``:
    {label: tips (n, 3) [m]}, NaN rows where a sample did not solve), each with its RMSE."""
    plt = _pyplot()
    measured = 1e3 * np.asarray(measured)
    fig, ax = plt.subplots(figsize=(10, 3.8))
    for k, (label, tips) in enumerate(predicted.items()):
        t = 1e3 * np.asarray(tips)
        ok = np.all(np.isfinite(t), axis=1)
        e = np.full(len(t), np.nan)
        e[ok] = np.linalg.norm(t[ok] + np.mean(measured[ok] - t[ok], axis=0) - measured[ok], axis=1)
        ax.plot(e, "-", color=f"C{k}", lw=1, label=f"{label}: RMSE {np.sqrt(np.nanmean(e**2)):.2f} mm")
    ax.set_xlabel("sample, in recorded order")
    ax.set_ylabel("tip error [mm]")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    return _finish(fig, path)


@_styled
def plot_contact_press(res: dict, path: str | Path | None = None, title: str | None = None):
    """The tip pressed on a table against insertion (``paper.contact_press``): the normal force on
    the table, and the tip compliance in contact beside the free robot's, along x (across the
    bending plane), y (the table's normal) and z (along the table in the bending plane)."""
    plt = _pyplot()
    d = 1e3 * np.asarray(res["insertion"])
    ok = np.asarray(res["result"]) == 0
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
    ax.plot(d[ok], np.asarray(res["force"])[ok], "o-", ms=4, label="on the table, total")
    ax.plot(d[ok], np.asarray(res["tip_force"])[ok], "x--", ms=5, label="at the tip")
    ax.set_xlabel("insertion $d$ [mm]")
    ax.set_ylabel("normal force [N]")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8)
    ax.set_title("how hard the tip presses", fontsize=10)
    for k, (axis, colour) in enumerate(zip("xyz", ("C0", "C2", "C1"), strict=True)):
        bx.plot(d[ok], 1e3 * np.asarray(res["free_compliance"])[ok, k, k], "--", color=colour, label=f"{axis}, free")
        bx.plot(d[ok], 1e3 * np.asarray(res["compliance"])[ok, k, k], "o-", ms=3, color=colour, label=f"{axis}, on the table")
    bx.set_yscale("symlog", linthresh=1e-2)
    bx.set_xlabel("insertion $d$ [mm]")
    bx.set_ylabel("tip compliance [mm/N]")
    bx.legend(fontsize=7, ncol=3)
    bx.set_title("the stiffness a hand feels at the tip", fontsize=10)
    if not ok.all():
        fig.text(0.01, 0.01, f"{np.count_nonzero(~ok)} insertions did not converge (not drawn)", fontsize=8, color="C3")
    if title:
        fig.suptitle(title)
    return _finish(fig, path)


@_styled
def plot_tip_path(traj, path: str | Path | None = None, title: str | None = None):
    """The tip of a simulated robot (``tdct.simulate``'s Trajectory) in mm: its x, y and z and the
    tendon tensions [N] against time [s], and its path seen along the base axis (x-y) and from the
    side (z-y), coloured by time, the start and the end marked.

    Args:
        traj: a Trajectory (JAX or numpy arrays).
        path: where to save a PNG; the figure is returned either way.
        title: figure title.
    """
    plt = _pyplot()
    t, tip, T = np.asarray(traj.t), 1e3 * np.asarray(traj.position)[:, -1], np.asarray(traj.tensions)
    fig = plt.figure(figsize=(16, 6.4), layout="constrained")
    grid = fig.add_gridspec(4, 3, width_ratios=(1.4, 1, 1))
    left = [fig.add_subplot(grid[0, 0])]
    left += [fig.add_subplot(grid[k, 0], sharex=left[0]) for k in range(1, 4)]
    least = max(1e-3, 1e-3 * np.ptp(tip, axis=0).max())  # a coordinate that moves less is drawn flat, not as round-off
    for k, ax in enumerate(left[:3]):
        ax.plot(t, tip[:, k], color=f"C{k}", lw=1.6)
        ax.set_ylabel(f"tip {'xyz'[k]} [mm]")
        ax.tick_params(labelbottom=False)
        ax.ticklabel_format(axis="y", useOffset=False)
        if np.ptp(tip[:, k]) < least:
            middle = (tip[:, k].max() + tip[:, k].min()) / 2
            ax.set_ylim(middle - least, middle + least)
    for j in range(T.shape[1]):
        left[3].plot(t, T[:, j], lw=1.4, label=f"tendon {j + 1}")
    if 0 < T.shape[1] <= 12:  # below the panel: a legend inside would hide the lines at 0
        left[3].legend(fontsize="small", ncols=min(T.shape[1], 3), loc="upper center", bbox_to_anchor=(0.5, -0.45))
    left[3].set_ylabel("tension [N]")
    left[3].set_xlabel("t [s]")
    left[3].xaxis.set_major_locator(_pyplot().MaxNLocator(6))
    paths = [fig.add_subplot(grid[:, 1]), fig.add_subplot(grid[:, 2])]
    for ax, (h, v), name in zip(
        paths, ((0, 1), (2, 1)), ("tip path seen along the base axis", "tip path, side view"), strict=True
    ):
        ax.plot(tip[:, h], tip[:, v], color="0.7", lw=1, zorder=1)
        dots = ax.scatter(tip[:, h], tip[:, v], c=t, cmap="viridis", s=9, zorder=2)
        ax.plot(*tip[0, [h, v]], "o", mfc="none", mec="black", ms=11, mew=1.5, label=f"start, t = {t[0]:g} s", zorder=3)
        ax.plot(*tip[-1, [h, v]], "s", mfc="none", mec="tab:red", ms=11, mew=1.5, label=f"end, t = {t[-1]:g} s", zorder=3)
        ax.set_xlabel(f"{'xyz'[h]} [mm]")
        ax.set_ylabel(f"{'xyz'[v]} [mm]")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(name)
    paths[0].legend(fontsize="small", loc="upper center", bbox_to_anchor=(0.5, -0.1), ncols=2)
    fig.colorbar(dots, ax=paths, label="t [s]", shrink=0.8)
    if title:
        fig.suptitle(title)
    return _finish(fig, path)


GIF_FPS = 20
"""Frames a second of ``animate_trajectory``'s GIFs (a GIF's frame delay is in hundredths of a
second, and viewers slow shorter delays than 2 of them)."""


@_styled
def animate_trajectory(
    traj, path: str | Path, frames: int = 60, title: str | None = None, progress=None, dpi: int = 80, scene=None
):
    """A GIF of a simulated robot's side view (world z-y, mm): its centreline at ``frames`` times
    spread evenly over the trajectory (every time when it has fewer), the tip's path so far and the
    start's centreline dashed, the time in each frame's title, and the obstacles of ``scene`` (the
    one it was simulated with) as ``plot_robot`` draws them; saved with Pillow at ``GIF_FPS``.

    Args:
        traj: a Trajectory (JAX or numpy arrays).
        path: the GIF to write.
        frames: the most frames.
        title: figure title.
        progress: called as ``progress(frame, frames)`` after each frame is drawn (a progress bar).
        dpi: pixels per inch of the 7 x 6.2 inch frames.

    Returns:
        The trajectory rows drawn, one per frame (ints).
    """
    from matplotlib.animation import FuncAnimation, PillowWriter

    plt = _pyplot()
    t, p = np.asarray(traj.t), 1e3 * np.asarray(traj.position)
    rows = np.unique(np.round(np.linspace(0, len(t) - 1, min(frames, len(t)))).astype(int))
    dt = t[1] - t[0] if len(t) > 1 else 1.0
    digits = max(0, -int(np.floor(np.log10(dt) + 1e-9)))  # the time to the step's last digit
    zy = p[rows][..., [2, 1]].reshape(-1, 2)
    if scene is not None:
        zy = np.concatenate([zy, _scene_points(scene, p[0])[:, [2, 1]]])
    middle, half = (zy.max(0) + zy.min(0)) / 2, 0.55 * max(np.ptp(zy, axis=0).max(), 1e-3)
    fig, ax = plt.subplots(figsize=(7, 6.2), layout="constrained")
    ax.set_xlim(middle[0] - half, middle[0] + half)
    ax.set_ylim(middle[1] - half, middle[1] + half)
    ax.set_aspect("equal", adjustable="box")
    ax.plot(p[0, :, 2], p[0, :, 1], "--", color="0.6", lw=1.5, label=f"t = {t[0]:g} s")
    body = ax.plot([], [], color="tab:blue", lw=3, solid_capstyle="round", label="centreline")[0]
    trace = ax.plot([], [], color="tab:red", lw=1, alpha=0.7, label="tip path")[0]
    tip = ax.plot([], [], "o", color="tab:red", ms=6)[0]
    ax.plot(0, 0, "ks", ms=8, label="base")
    if scene is not None:
        _draw_scene(ax, scene, (2, 1), p.reshape(-1, 3))
        ax.fill([], [], color=OBSTACLE, alpha=0.35, label=f"obstacles: {', '.join(scene.names)}")
    ax.set_xlabel("z [mm]")
    ax.set_ylabel("y [mm]")
    ax.legend(loc="best", fontsize="small")
    if title:
        fig.suptitle(title, fontsize="medium")

    def draw(k):
        i = rows[k]
        body.set_data(p[i, :, 2], p[i, :, 1])
        trace.set_data(p[: i + 1, -1, 2], p[: i + 1, -1, 1])
        tip.set_data(p[i, -1, 2:3], p[i, -1, 1:2])
        ax.set_title(f"side view, t = {t[i]:.{digits}f} s")
        return body, trace, tip

    animation = FuncAnimation(fig, draw, frames=len(rows), blit=False)
    animation.save(path, writer=PillowWriter(fps=GIF_FPS), dpi=dpi, progress_callback=progress)
    plt.close(fig)
    return rows
