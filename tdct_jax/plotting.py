"""Figures (the only module that imports matplotlib). Axes in millimetres and degrees."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .shooting import Solution


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_shape(sol: Solution, insertion: float, path: str | Path | None = None, title: str | None = None):
    """Side view (world z-y plane) and 3D view of one solved shape; the tube part drawn thick.

    Args:
        sol: a single (unbatched) Solution.
        insertion: tube insertion depth d [m], to mark the backbone segment [0, d].
        path: where to save a PNG; the figure is returned either way.
        title: figure title.
    """
    plt = _pyplot()
    p = np.asarray(sol.position) * 1e3
    tube = np.asarray(sol.s) <= insertion + 1e-12 if insertion > 0 else np.zeros(len(p), bool)
    fig = plt.figure(figsize=(11, 4.6))
    ax = fig.add_subplot(1, 2, 1)
    ax.plot(p[:, 2], p[:, 1], color="tab:blue", lw=2, label="silicone only")
    if tube.any():
        ax.plot(p[tube, 2], p[tube, 1], color="black", lw=4, label=f"with Nitinol tube (d = {insertion * 1e3:.0f} mm)")
    ax.plot(*p[-1, [2, 1]], "o", color="tab:red", label="tip")
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
    ax3.set_xlabel("x [mm]")
    ax3.set_ylabel("z [mm]")
    ax3.set_zlabel("y [mm]")
    span = max(np.ptp(p, axis=0).max(), 1.0) / 2
    mid = (p.max(0) + p.min(0)) / 2
    ax3.set_xlim(mid[0] - span, mid[0] + span)
    ax3.set_ylim(mid[2] - span, mid[2] + span)
    ax3.set_zlim(mid[1] - span, mid[1] + span)
    ax3.set_title("3D (gravity along -y)")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig


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
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


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
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig


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
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig
