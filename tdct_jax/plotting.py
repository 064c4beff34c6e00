"""Figures (the only module that imports matplotlib). Axes in millimetres and degrees."""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np

from .solve import Solution


def _pyplot():
    import matplotlib

    if "inline" not in matplotlib.get_backend():  # keep Jupyter's inline figures
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _finish(fig, path):
    """Saves the figure as a PNG when a path is given (and closes it); returns it either way."""
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
        _pyplot().close(fig)
    return fig


def _tube_mask(s, insertion):
    """True at the nodes inside the tube, [0, d]."""
    return np.asarray(s) <= insertion + 1e-12 if insertion > 0 else np.zeros(np.shape(s), bool)


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
    ax.legend(loc="best", fontsize=8)
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
    ax.legend(loc="best", fontsize=7)
    ax.grid(alpha=0.3)
    _equal_3d(ax3, np.concatenate(every))
    ax3.set_title("3D (paper Fig. 7)")
    if title:
        fig.suptitle(title)
    return _finish(fig, path)


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
    ax.legend(fontsize=8)
    _finish(fig, path)


def plot_compliance_ellipses(CMs: dict, path: str | Path | None = None, title: str | None = None):
    """Compliance ellipsoids {CM f : |f| = 1} projected on the plane of the first one's two largest
    axes (paper Fig. 10), in mm/N.

    Args:
        CMs: label -> 3x3 compliance matrix [m/N]; the first sets the projection plane.
        path: where to save a PNG; the figure is returned either way.
        title: axes title.
    """
    plt = _pyplot()
    mats = {k: np.asarray(v) * 1e3 for k, v in CMs.items()}
    U, _, _ = np.linalg.svd(next(iter(mats.values())))
    plane = U[:, :2]
    t = np.linspace(0, 2 * np.pi, 200)
    fig, ax = plt.subplots(figsize=(5.6, 5.2))
    for label, CM in mats.items():
        u, s, _ = np.linalg.svd(plane.T @ CM)
        xy = u @ (s[:, None] * np.stack([np.cos(t), np.sin(t)]))
        ax.plot(xy[0], xy[1], lw=2, label=label)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("along the major axis [mm/N]")
    ax.set_ylabel("along the second axis [mm/N]")
    ax.set_title(title or "compliance ellipse (tip displacement per N of tip force)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _finish(fig, path)


def plot_fig11(tensions, insertions, lam, path: str | Path | None = None):
    """Paper Fig. 11: lambda_1..3 of CM [mm/N] against insertion depth [mm], one colour per tension."""
    plt = _pyplot()
    d_mm = np.asarray(insertions) * 1e3
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2))
    colours = plt.cm.viridis(np.linspace(0, 0.9, len(tensions)))
    for k, ax in enumerate(axes):
        for tau, c, row in zip(tensions, colours, np.asarray(lam), strict=True):
            ax.plot(d_mm, row[:, k] * 1e3, "o-", ms=3, color=c, label=f"{tau:g} N")
        ax.set_xlabel("insertion depth [mm]")
        ax.set_ylabel(f"lambda_{k + 1} [mm/N]")
        ax.grid(alpha=0.3)
    axes[0].legend(title="tendon 1 tension", fontsize=8)
    fig.suptitle("Eigenvalues of the tip compliance matrix (paper Fig. 11)")
    return _finish(fig, path)


def plot_fig8a(res, path: str | Path | None = None):
    """Paper Fig. 8A: side views of the shape as the tube goes in; arrow: the tip's motion.

    Args:
        res: SweepResult of ``paper.fig8a_shapes`` (shapes=True; insertion axis first).
    """
    plt = _pyplot()
    depths = np.asarray(res.axes["insertion"])
    tension = float(np.asarray(res.axes["tensions"])[0, 0])
    fig, ax = plt.subplots(figsize=(7.5, 5.2))
    colours = plt.cm.plasma(np.linspace(0, 0.85, len(depths)))
    for i, (d, c) in enumerate(zip(depths, colours, strict=True)):
        p = res.position[i, 0] * 1e3
        tube = _tube_mask(res.s[i, 0], d)
        ax.plot(p[:, 2], p[:, 1], color=c, lw=2, zorder=3, label=f"d = {d * 1e3:.0f} mm")
        if tube.any():
            ax.plot(p[tube, 2], p[tube, 1], color="black", lw=6, zorder=2, solid_capstyle="butt")
            ax.plot(*p[tube][-1, [2, 1]], "o", mfc="white", mec="black", ms=6, zorder=4)
    ax.plot([], [], color="black", lw=6, label="inside the tube")
    ax.plot([], [], "o", mfc="white", mec="black", ms=6, label="tube end (s = d)")
    tips = res.tip_position[:, 0] * 1e3
    ax.annotate("", xy=tips[-1, [2, 1]], xytext=tips[0, [2, 1]], arrowprops=dict(arrowstyle="->", color="red", lw=2))
    ax.axhline(0, color="0.8", lw=0.8, zorder=0)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("z [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title(f"Shape as the tube is inserted: {tension:g} N on tendon 1, no tip load (paper Fig. 8A)")
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(alpha=0.3)
    return _finish(fig, path)


def plot_fig8b(res, path: str | Path | None = None):
    """Paper Fig. 8B: tip workspace without (curve, d = 0) and with the insertion degree of freedom.

    Args:
        res: SweepResult of ``paper.tip_pose_grid`` (tension axis first, insertion second).
    """
    plt = _pyplot()
    tip = res.tip_position * 1e3
    fig, ax = plt.subplots(figsize=(6.8, 5.6))
    ax.plot(tip[..., 2].ravel(), tip[..., 1].ravel(), ".", color="0.6", ms=4, label="grid points (tension x insertion)")
    edge = np.concatenate([tip[:, 0], tip[-1, 1:], tip[::-1, -1][1:], tip[0, ::-1][1:]])
    ax.plot(edge[:, 2], edge[:, 1], "--", color="red", lw=1.8, label="workspace with insertion")
    ax.plot(tip[:, 0, 2], tip[:, 0, 1], "-", color="black", lw=2.5, label="tendon only (d = 0 mm)")
    depths = np.asarray(res.axes["insertion"]) * 1e3
    taus = np.asarray(res.axes["tensions"])[:, 0]
    ax.set_xlabel("z_tip [mm]")
    ax.set_ylabel("y_tip [mm]")
    ax.set_title(f"Tip workspace: tendon 1 at {taus[0]:g}-{taus[-1]:g} N, insertion {depths[0]:g}-{depths[-1]:g} mm")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _finish(fig, path)


def plot_fig9(res, path: str | Path | None = None):
    """Paper Fig. 9A-C: z_tip, y_tip [mm] and theta_tip [deg] against insertion, one line per tension."""
    plt = _pyplot()
    depths = np.asarray(res.axes["insertion"]) * 1e3
    taus = np.asarray(res.axes["tensions"])[:, 0]
    values = (res.tip_position[..., 2] * 1e3, res.tip_position[..., 1] * 1e3, np.degrees(res.tip_angle))
    labels = ("(A) z_tip [mm]", "(B) y_tip [mm]", "(C) theta_tip [deg]")
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.4))
    colours = plt.cm.viridis(np.linspace(0, 0.95, len(taus)))
    for ax, v, label in zip(axes, values, labels, strict=True):
        for tau, c, row in zip(taus, colours, v, strict=True):
            ax.plot(depths, row, "o-", ms=2.5, color=c, label=f"{tau:g} N")
        ax.set_xlabel("insertion depth [mm]")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[2].legend(title="tendon 1 tension", fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    fig.suptitle("Tip pose against tube insertion, no tip load (paper Fig. 9)")
    return _finish(fig, path)


def plot_fig13(results: dict, path: str | Path | None = None):
    """Paper Fig. 13: y_tip [mm] against insertion [mm] for several tip masses, optimum as a black dot.

    Args:
        results: {tension [N]: GridResult of ``paper.fig13_optima``}, one panel each.
    """
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(results), figsize=(6.2 * len(results) + 1.3, 4.6), squeeze=False)
    all_masses = [np.asarray(r.axes["tip_mass"]).tolist() for r in results.values()]
    shared = all(m == all_masses[0] for m in all_masses)  # then one legend serves every panel
    for k, (ax, (tension, r), letter) in enumerate(zip(axes[0], results.items(), "ABCD", strict=False)):
        masses = np.asarray(r.axes["tip_mass"]) * 1e3
        colours = plt.cm.cividis(np.linspace(0, 0.9, len(masses)))
        for i, (m, c) in enumerate(zip(masses, colours, strict=True)):
            ax.plot(r.curve_insertion * 1e3, r.curve_height[i] * 1e3, "-", color=c, label=f"{m:g} g")
            ax.plot(r.insertion[i] * 1e3, r.height[i] * 1e3, "o", color="black", ms=5)
        ax.plot([], [], "o", color="black", ms=5, label="maximum of y_tip")
        ax.set_xlabel("insertion depth [mm]")
        ax.set_ylabel("y_tip [mm]")
        ax.set_title(f"({letter}) tendon 1 at {tension:g} N")
        ax.grid(alpha=0.3)
        if not shared or k == len(results) - 1:
            ax.legend(title="tip mass", fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    fig.suptitle("Tip height against insertion for several tip masses (paper Fig. 13)")
    return _finish(fig, path)


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
    fig, ax = plt.subplots(figsize=(8.2, 4.8))
    colours = plt.cm.viridis(np.linspace(0, 0.9, len(taus)))
    for i, (tau, c) in enumerate(zip(taus, colours, strict=True)):
        ax.plot(depths, res.mass[i] * 1e3, "o-", ms=3, color=c, label=f"{tau:g} N")
        if paper_points is not None:
            d, g = paper_points
            ax.plot(np.asarray(d) * 1e3, np.asarray(g)[:, i], "x", color=c, ms=9, mew=2)
    if paper_points is not None:
        ax.plot([], [], "x", color="black", ms=9, mew=2, label="paper (Sec. V.A)")
    ax.set_xlabel("insertion depth [mm]")
    ax.set_ylabel("load capacity (tip reaches y = 0) [g]")
    ax.set_title("Tip load capacity against insertion (paper Fig. 14)")
    ax.grid(alpha=0.3)
    ax.legend(title="tendon 1 tension", fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return _finish(fig, path)


def plot_tip_angle_family(family, path: str | Path | None = None):
    """Sec. V.B: tip angle against insertion at fixed tip heights (left), and the range of angles
    each height allows (right), against the single angle of the tendon-only robot."""
    plt = _pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.4))
    colors = plt.cm.viridis(np.linspace(0, 0.9, len(family.heights)))
    d_mm = family.insertions * 1e3
    low, high, plain = [], [], []
    for k, (h, c) in enumerate(zip(family.heights, colors, strict=True)):
        ok = family.reached[k]
        angle = np.degrees(np.where(ok, family.tip_angle[k], np.nan))
        ax.plot(d_mm, angle, "o-", color=c, ms=3, label=f"y = {h * 1e3:g} mm")
        low.append(np.nanmin(angle) if ok.any() else np.nan)
        high.append(np.nanmax(angle) if ok.any() else np.nan)
        plain.append(angle[0] if ok[0] else np.nan)
    ax.set(xlabel="tube insertion [mm]", ylabel="tip angle [deg]", title="tip held at a height, tendon 1 re-solved")
    ax.legend(fontsize=8, title="tip height", title_fontsize=8)
    ax.grid(alpha=0.3)
    y_mm = family.heights * 1e3
    bx.fill_betweenx(y_mm, low, high, color="tab:blue", alpha=0.25, label="reachable with the tube")
    bx.plot(low, y_mm, color="tab:blue")
    bx.plot(high, y_mm, color="tab:blue")
    bx.plot(plain, y_mm, "ks", label="tendon 1 alone (no tube)")
    bx.set(xlabel="tip angle [deg]", ylabel="tip height y [mm]", title="range of tip angles at each height")
    bx.legend(fontsize=8, loc="lower right")
    bx.grid(alpha=0.3)
    fig.suptitle("Sec. V.B: the tube insertion as a redundant input for the tip angle")
    return _finish(fig, path)


def plot_stiffest_reach(reach, optimum=None, path: str | Path | None = None):
    """Sec. V.A as IK: the stiffest actuation for each target height (insertion and tension), and
    its compliance along -y against the tendon-only actuation's. ``optimum``: (highest height [m],
    its insertion [m]) from the optimal-insertion study, marked."""
    plt = _pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.2))
    y_mm = reach.heights * 1e3
    ax.plot(np.where(reach.reached, reach.insertion * 1e3, np.nan), y_mm, "o-", color="tab:blue", label="stiffest: insertion")
    if optimum is not None:
        ax.plot(optimum[1] * 1e3, optimum[0] * 1e3, "r*", ms=12, label=f"highest reach ({optimum[1] * 1e3:.0f} mm of tube)")
        ax.axvline(70, color="0.5", ls="--", lw=1, label="paper: 70 mm (grid search)")
    ax.set(xlabel="tube insertion [mm]", ylabel="target tip height y [mm]", title=f"{reach.mass * 1e3:g} g at the tip")
    ax.legend(fontsize=8, loc="lower left")
    ax.grid(alpha=0.3)
    tx = ax.twiny()
    tx.plot(np.where(reach.reached, reach.tension, np.nan), y_mm, "s--", color="tab:orange", ms=4)
    tx.set_xlabel("tendon 1 tension [N] (orange)", color="tab:orange")
    bx.plot(reach.compliance * 1e3, y_mm, "o-", color="tab:blue", label="stiffest (tendon 1 + tube)")
    bx.plot(reach.tendon_only_compliance * 1e3, y_mm, "s-", color="0.4", label="tendon 1 alone (no tube)")
    bx.set(xlabel="tip compliance along -y [mm/N]", ylabel="target tip height y [mm]", title="what the tube buys in stiffness")
    bx.legend(fontsize=8)
    bx.grid(alpha=0.3)
    fig.suptitle("Sec. V.A as inverse kinematics: reach a height with the stiffest actuation")
    return _finish(fig, path)


def plot_stiffness_map(stiffness, path: str | Path | None = None):
    """Tip compliance along -y over in-plane targets: least-tension solution, and how much lower the
    stiffest (the redundant input chosen for stiffness) is [%]."""
    plt = _pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.6), sharey=True)
    z, y = stiffness.z.ravel() * 1e3, stiffness.y.ravel() * 1e3
    gain = 100 * (1 - stiffness.stiffest / stiffness.least_tension).ravel()
    for axis, value, label, cmap in (
        (ax, stiffness.least_tension.ravel() * 1e3, "least-tension compliance along -y [mm/N]", "magma_r"),
        (bx, gain, "stiffest: compliance lower by [%]", "viridis"),
    ):
        reached = np.isfinite(value)
        im = axis.scatter(z[reached], y[reached], c=value[reached], cmap=cmap, s=50, edgecolors="none")
        axis.scatter(z[~reached], y[~reached], marker="x", color="0.5", s=30, label="not reached")
        fig.colorbar(im, ax=axis, label=label)
        axis.set(xlabel="target z [mm]")
        axis.grid(alpha=0.3)
    ax.set(ylabel="target y [mm]", title="least-tension solution")
    bx.set(title="stiffest solution against it")
    if not np.all(np.isfinite(gain)):
        bx.legend(loc="best", fontsize=8)
    fig.suptitle("Tendons 1 and 3 with the tube, targets in the z-y plane: where redundancy buys stiffness")
    return _finish(fig, path)
