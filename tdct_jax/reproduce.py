"""``tdct reproduce``: every simulation figure and headline number of the paper in one run.

Writes PNG figures (Figs. 8A, 8B, 9, 10, 11, 13, 14, and beyond the paper Sec. V.A's highest reach
and stiffest reach, Sec. V.B's tip angles and a stiffness map) and summary.md / summary.json, which
put each headline number beside the paper's with the relative difference. Every study shows its
progress on stderr (progress bars, step headers).
"""

from __future__ import annotations

import json
import platform
import sys
from pathlib import Path
from time import perf_counter

import jax
import numpy as np

from . import fields, paper, plotting
from .description import Robot
from .inputs import Actuation, Loads

FULL = dict(
    fig8a_insertions=paper.FIG8A_INSERTIONS,
    fig9_tensions=paper.FIG9_TENSIONS,
    fig9_insertions=paper.FIG9_INSERTIONS,
    fig11_tensions=paper.FIG11_TENSIONS,
    fig11_insertions=paper.FIG11_INSERTIONS,
    fig13_masses=paper.FIG13_MASSES,
    fig13_curve=33,
    fig14_insertions=paper.FIG9_INSERTIONS,
    table3=(paper.TABLE3_TENSIONS, paper.TABLE3_INSERTIONS, paper.TABLE3_MASSES),
    vb=(paper.VB_HEIGHTS, paper.VB_INSERTIONS),
    va_heights=paper.VA_HEIGHTS,
    stiffness_map=(paper.MAP_TENSIONS, paper.MAP_INSERTIONS),
    fit=True,
    contact_insertions=paper.CONTACT_INSERTIONS,
)
"""The paper's grids."""
QUICK = dict(
    fig8a_insertions=(0.0, 0.075, 0.15),
    fig9_tensions=(0.0, 5.0, 10.0),
    fig9_insertions=(0.0, 0.05, 0.10, 0.15),
    fig11_tensions=(0.0, 6.0),
    fig11_insertions=(0.0, 0.15),
    fig13_masses=(0.0, 0.05),
    fig13_curve=9,
    fig14_insertions=(0.0, 0.07, 0.15),
    table3=((0.0, 10.0), (0.0, 0.12), (0.0, 0.05)),
    vb=((0.0, 0.04), (0.0, 0.08, 0.16)),
    va_heights=None,
    stiffness_map=None,
    fit=False,
    contact_insertions=(0.0, 0.08, 0.16),
)
"""Coarse grids (for CI and a first look); the ten load capacities are computed in full either way;
no Sec. V.A as inverse kinematics, no stiffness map and no parameter fit (each compiles programs of
its own that take tens of seconds)."""


def _relative(model: float, reference: float) -> float:
    return (model - reference) / abs(reference)


def reproduce(
    out: str | Path = "tdct-reproduce", *, quick: bool = False, robot: Robot | None = None, progress: bool = True
) -> dict:
    """Runs every study, writes the figures and the summary into ``out``; returns the summary.

    Args:
        out: output folder (created).
        quick: coarse grids and no parameter fit (see QUICK).
        robot: the robot (default: ``Robot.paper()``).
        progress: progress bars and step headers on stderr.
    """
    robot = Robot.paper() if robot is None else robot
    grids = QUICK if quick else FULL
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    start = perf_counter()
    opts = dict(progress=progress, throw=False)  # failures are reported in the summary
    rows: list[dict] = []
    timings: dict[str, float] = {}
    steps = [
        ("Fig. 8A: shapes as the tube goes in", "fig8a"),
        ("Figs. 8B and 9: tip pose on the tension x insertion grid", "fig9"),
        ("Fig. 10: compliance ellipses", "fig10"),
        ("Fig. 11: compliance eigenvalues", "fig11"),
        ("Fig. 13: optimal insertion", "fig13"),
        ("Fig. 14 and Sec. V.A: load capacity", "fig14"),
        ("Sec. III.B: bending-angle range over the Table III conditions", "table3"),
    ]
    steps.append(("Beyond the paper: the tip pressed on a table, the body over a cylinder (contact)", "contact"))
    steps.append(("Sec. V.B: the tip angles the tube allows at fixed tip heights (inverse kinematics)", "vb"))
    if grids["va_heights"]:
        steps.append(("Sec. V.A: the highest reach with 50 g, and the stiffest way to each lower height (IK)", "va_ik"))
    if grids["stiffness_map"]:
        steps.append(("Stiffness map: least tension against stiffest, tendons 1 and 3 with the tube", "stiffness_map"))
    if grids["fit"]:
        steps.append(("Sec. V.A: fit of tendon offset and density to the ten load capacities", "fit"))

    def say(text):
        if progress:
            print(text, file=sys.stderr, flush=True)

    for k, (title, key) in enumerate(steps, 1):
        say(f"[{k}/{len(steps)}] {title}")
        t0 = perf_counter()
        rows += _STUDIES[key](robot, grids, out, opts, say)
        timings[key] = perf_counter() - t0

    total = perf_counter() - start
    summary = dict(
        quick=quick,
        total_seconds=total,
        seconds_per_study=timings,
        machine=f"{platform.machine()}, {jax.device_count()} x {jax.devices()[0].platform}, jax {jax.__version__}",
        robot={name: np.asarray(fields.get(robot, name)).tolist() for name in fields.names(robot)},
        headlines=rows,
        figures=sorted(p.name for p in out.glob("*.png")),
    )
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    (out / "summary.md").write_text(_markdown(summary))
    say(f"done in {total:.0f} s: {out / 'summary.md'}")
    return summary


def _row(quantity: str, model: float, reference: float | None, unit: str, note: str = "") -> dict:
    return dict(
        quantity=quantity,
        model=float(model),
        paper=None if reference is None else float(reference),
        unit=unit,
        relative_difference=None if reference is None else _relative(float(model), float(reference)),
        note=note,
    )


def _fig8a(robot, grids, out, opts, say):
    res = paper.fig8a_shapes(robot, insertions=grids["fig8a_insertions"], **opts)
    plotting.plot_fig8a(res, out / "fig8a_shapes.png")
    return []


def _fig9(robot, grids, out, opts, say):
    res = paper.tip_pose_grid(robot, grids["fig9_tensions"], grids["fig9_insertions"], **opts)
    plotting.plot_fig8b(res, out / "fig8b_workspace.png")
    plotting.plot_fig9(res, out / "fig9_tip_pose.png")
    res.save_csv(out / "fig9_tip_pose.csv")
    return []


def _fig10(robot, grids, out, opts, say):
    CMs = {k.removeprefix("insertion "): v for k, v in paper.fig10_compliances(robot, paper.FIG10_TENSION).items()}
    title = f"Compliance ellipses (paper Fig. 10)\n{paper.FIG10_TENSION:g} N on tendon 1, no tip load"
    plotting.plot_compliance_ellipses(CMs, out / "fig10_compliance_ellipses.png", title=title, legend_title="insertion $d$")
    return []


def _fig11(robot, grids, out, opts, say):
    tensions, insertions = grids["fig11_tensions"], grids["fig11_insertions"]
    lam = paper.fig11_eigenvalues(robot, tensions, insertions, **opts)
    plotting.plot_fig11(tensions, insertions, lam, out / "fig11_compliance_eigenvalues.png")
    i = int(np.argmin(np.abs(np.asarray(tensions) - 6.0)))
    h = paper.compliance_headline(tensions, insertions, lam)[i]
    where = f"tendon 1 at {h['tension_N']:g} N"
    p0, p1 = h["paper_lambda2_mm_per_N"]
    return [
        _row(f"lambda_2 at insertion {h['insertion_mm'][0]:g} mm", h["lambda2_mm_per_N"][0], p0, "mm/N", where),
        _row(f"lambda_2 at insertion {h['insertion_mm'][1]:g} mm", h["lambda2_mm_per_N"][1], p1, "mm/N", where),
        _row("compliance reduction by the tube", h["reduction_percent"], h["paper_reduction_percent"], "%", where),
    ]


def _fig13(robot, grids, out, opts, say):
    results = {t: paper.fig13_optima(robot, t, grids["fig13_masses"], grids["fig13_curve"], **opts) for t in paper.FIG13_TENSIONS}
    plotting.plot_fig13(results, out / "fig13_optimal_insertion.png")
    target = paper.PAPER_OPTIMUM
    r = results[target["tension_N"]]
    i = int(np.argmin(np.abs(np.asarray(r.axes["tip_mass"]) - target["mass_g"] * paper.G)))
    note = f"{r.axes['tip_mass'][i] / paper.G:g} g at {target['tension_N']:g} N; converged: {bool(r.converged[i])}"
    return [_row("optimal insertion", 1e3 * r.insertion[i], target["insertion_mm"], "mm", note)]


def _fig14(robot, grids, out, opts, say):
    res = paper.fig14_capacities(robot, insertions=grids["fig14_insertions"], **opts)
    ten = paper.ten_capacities(robot, **opts)
    plotting.plot_fig14(res, (paper.CAPACITY_INSERTIONS, paper.PAPER_CAPACITIES_G), out / "fig14_load_capacity.png")
    rows = []
    # Robot.paper()'s tendon offset and density are the fit to these ten capacities (_fit)
    fitted = all(fields.get(robot, k) == fields.get(Robot.paper(), k) for k in ("tendons[*].offset", "sections[*].density"))
    for i, d in enumerate(paper.CAPACITY_INSERTIONS):
        for j, t in enumerate(paper.CAPACITY_TENSIONS):
            ok = bool(ten.converged[i, j])
            note = f"tube {1e3 * d:g} mm, tendon 1 at {t:g} N" + ("" if ok else "; NOT converged")
            note += "; tendon offset and density fitted to these ten capacities: not an independent check" if fitted else ""
            rows.append(_row("load capacity", ten.mass[i, j] / paper.G, paper.PAPER_CAPACITIES_G[i][j], "g", note))
    return rows


def _table3(robot, grids, out, opts, say):
    res = paper.bending_range(robot, *grids["table3"], **opts)
    angles = np.degrees(res.tip_angle[res.converged])
    lo, hi = paper.PAPER_BENDING_RANGE_DEG
    note = f"{res.converged.size} conditions, {res.n_failed} not converged"
    return [
        _row("smallest bending angle", angles.min(), lo, "deg", note),
        _row("largest bending angle", angles.max(), hi, "deg", note),
    ]


def _fit(robot, grids, out, opts, say):
    offset, density = "tendons[*].offset", "sections[*].density"
    start = robot.replace({offset: 6e-3, density: 1130.0})
    say("  from tendon offset 6 mm and the handbook density 1130 kg/m^3")
    rows = []
    for params in ((offset,), (offset, density)):
        fit = paper.fit_load_capacities(start, params, progress=say if opts["progress"] else None)
        rms = float(np.sqrt(np.mean(np.square(fit.residual_percent))))
        note = f"fit of {' and '.join(params)}: rms misfit {rms:.2f}%, worst {np.abs(fit.residual_percent).max():.2f}%"
        note += f", {fit.iterations} iterations" + ("" if fit.converged else ", NOT converged")
        rows.append(_row("fitted tendon offset", 1e3 * fit.values[offset], None, "mm", note))
        if density in fit.values:
            rows.append(_row("fitted effective silicone density", fit.values[density], None, "kg/m^3", note))
    return rows


def _vb(robot, grids, out, opts, say):
    heights, insertions = grids["vb"]
    family = paper.tip_angle_family(robot, heights, insertions, progress=opts["progress"])
    plotting.plot_tip_angle_family(family, out / "fig16_tip_angle_redundancy.png")
    rows = []
    for k, h in enumerate(family.heights):
        ok = family.reached[k]
        angles = np.degrees(family.tip_angle[k][ok])
        note = f"tendon 1 up to 10 N, tube 0-{1e3 * family.insertions[-1]:g} mm; {ok.sum()} of {ok.size} depths reach it"
        spread = angles.max() - angles.min() if ok.any() else np.nan
        rows.append(_row(f"tip-angle range at tip height {1e3 * h:g} mm", spread, None, "deg", note))
    return rows


def _va_ik(robot, grids, out, opts, say):
    top = paper.highest_reach(robot, **opts)
    reach = paper.stiffest_reach(robot, grids["va_heights"], progress=opts["progress"])
    plotting.plot_stiffest_reach(reach, top, out / "fig13c_stiffest_reach.png")
    missed = int((~reach.reached).sum())
    height_note = f"maximum over tendon 1 in 0-{top.tension_bound:g} N and the tube in 0-{1e3 * robot.length:g} mm"
    height_note += f"; fig13c: the stiffest way to {len(reach.heights)} lower heights (IK)"
    height_note += f", {missed} NOT reached" if missed else ""
    note = (
        f"{top.mass / paper.G:g} g: tendon 1 on its {top.tension_bound:g} N bound (dy/dtau {1e3 * top.slope_tension:+.2f} mm/N)"
    )
    note += f", dy/dd {top.slope_insertion:.0e}; the paper's is read off a 10 mm grid"
    note += ("" if top.on_bound else "; grid maximum NOT on the tension bound") + ("" if top.converged else "; NOT converged")
    return [
        _row("highest tip height with 50 g", 1e3 * top.height, None, "mm", height_note),
        _row("insertion for the highest reach", 1e3 * top.insertion, paper.PAPER_OPTIMUM["insertion_mm"], "mm", note),
    ]


def _stiffness_map(robot, grids, out, opts, say):
    tensions, insertions = grids["stiffness_map"]
    m = paper.stiffness_map(robot, tensions, insertions, progress=opts["progress"])
    plotting.plot_stiffness_map(m, out / "stiffness_map.png")
    gain = 100 * (1 - m.stiffest / m.least_tension)
    note = f"{np.isfinite(gain).sum()} of {gain.size} in-plane targets reached by both, tendons 1 and 3 and the tube"
    return [
        _row("stiffest against least tension: largest compliance reduction", np.nanmax(gain), None, "%", note),
        _row("stiffest against least tension: median compliance reduction", np.nanmedian(gain), None, "%", note),
    ]


def _contact(robot, grids, out, opts, say):
    res = paper.contact_press(robot, insertions=grids["contact_insertions"], progress=opts["progress"])
    title = f"tip on a table {-1e3 * paper.TABLE_HEIGHT:g} mm below the axis, tendon 3 at {paper.CONTACT_TENSION:g} N"
    plotting.plot_contact_press(res, out / "contact_press.png", title=title)
    sol, scene, act = paper.body_contact(robot)
    load = Loads().with_scene(scene)
    title = f"over a cylinder, tendon 3 at {paper.CYLINDER_TENSION:g} N, no tube"
    plotting.plot_robot(sol, robot, Actuation.of(act, robot), load, out / "contact_cylinder.png", title=title)
    ok = res["result"] == 0
    note = f"tendon 3 at {paper.CONTACT_TENSION:g} N; {np.count_nonzero(~ok)} of {ok.size} insertions not converged"
    f = np.where(ok, res["force"], np.nan)
    free, held = res["free_compliance"][:, 0, 0], res["compliance"][:, 0, 0]
    return [
        _row("tip force on the table, no tube", f[0], None, "N", note),
        _row("tip force on the table, full tube", f[-1], None, "N", note),
        _row("lateral tip compliance on the table over free, no tube", 100 * held[0] / free[0], None, "%", note),
        _row("body force on the cylinder", float(np.sum(sol.contact.force)), None, "N", "tendon 3 at 10 N, no tube"),
    ]


_STUDIES = dict(
    fig8a=_fig8a,
    fig9=_fig9,
    fig10=_fig10,
    fig11=_fig11,
    fig13=_fig13,
    fig14=_fig14,
    table3=_table3,
    vb=_vb,
    va_ik=_va_ik,
    stiffness_map=_stiffness_map,
    fit=_fit,
    contact=_contact,
)


def _markdown(summary: dict) -> str:
    lines = [
        "# tdct reproduce: the paper's simulation results" + (" (quick grids)" if summary["quick"] else ""),
        "",
        f"Total time {summary['total_seconds']:.1f} s on {summary['machine']} (compiles included).",
        "",
        "| quantity | tdct_jax | paper | unit | difference | conditions |",
        "|---|---:|---:|---|---:|---|",
    ]
    for r in summary["headlines"]:
        paper_value = "" if r["paper"] is None else f"{r['paper']:.4g}"
        diff = "" if r["relative_difference"] is None else f"{100 * r['relative_difference']:+.1f}%"
        lines.append(f"| {r['quantity']} | {r['model']:.4g} | {paper_value} | {r['unit']} | {diff} | {r['note']} |")
    lines += ["", "Seconds per study: " + ", ".join(f"{k} {v:.1f}" for k, v in summary["seconds_per_study"].items()), ""]
    lines += ["Figures: " + ", ".join(summary["figures"]), ""]
    return "\n".join(lines)
