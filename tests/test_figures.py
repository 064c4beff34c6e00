"""The figures of ``tdct reproduce`` say what they show: drawn from small synthetic results (no
solves), each is checked for the property a reader relies on (one highest-reach marker, a legend
entry per curve, equal scales, a legend clear of the data, discrete heights drawn as such, math
labels); ``STYLE`` is applied while drawing and leaves the global rcParams as they were."""

from types import SimpleNamespace

import matplotlib
import numpy as np

from tdct_jax import paper, plotting

matplotlib.use("Agg")


def _legend_texts(fig):
    legends = [*fig.legends, *(a.get_legend() for a in fig.axes if a.get_legend() is not None)]
    return [t.get_text() for legend in legends for t in legend.get_texts()]


def _highest_and_reach():
    heights = np.array([-0.06, -0.04, -0.02, -0.01])
    reach = paper.StiffestReach(
        heights=heights,
        mass=0.05,
        tension=np.array([0.3, 4.5, 8.4, 10.0]),
        insertion=np.array([0.16, 0.16, 0.16, 0.139]),
        compliance=np.array([0.057, 0.067, 0.075, 0.078]),
        reached=np.ones(4, bool),
        tendon_only_tension=np.array([6.5, 8.6, np.nan, np.nan]),
        tendon_only_compliance=np.array([0.109, 0.138, np.nan, np.nan]),
    )
    top = paper.HighestReach(
        height=-5.5e-4,
        tension=10.0,
        insertion=0.0642,
        compliance=0.106,
        slope_insertion=0.0,
        slope_tension=8.8e-3,
        on_bound=True,
        converged=True,
        mass=0.05,
        tension_bound=10.0,
        grid_tensions=np.array([0.0, 10.0]),
        grid_insertions=np.array([0.0, 0.16]),
        grid_height=np.zeros((2, 2)),
    )
    return top, reach


def test_fig13c_has_one_highest_reach_and_a_legend_entry_per_curve():
    top, reach = _highest_and_reach()
    fig = plotting.plot_stiffest_reach(reach, top)
    texts = _legend_texts(fig)
    assert sum("highest reach" in t for t in texts) == 1
    assert any("tension" in t for t in texts) and any("insertion" in t for t in texts)
    stars = [line for a in fig.axes for line in a.get_lines() if line.get_marker() == "*"]
    left = [line for line in stars if line.axes is fig.axes[0]]
    assert len(left) == 1 and np.allclose(left[0].get_xydata(), [[64.2, -0.55]])
    # every curve ends at the highest reach: the insertion curve's last point is the marker
    (curve,) = [line for line in fig.axes[0].get_lines() if line.get_marker() == "o"]
    assert np.allclose(curve.get_xydata()[-1], [64.2, -0.55])


def test_fig8b_is_at_equal_scales_with_the_insertion_as_a_band():
    taus, depths = np.linspace(0, 10, 4), np.linspace(0, 0.15, 3)
    t, d = np.meshgrid(taus, depths, indexing="ij")
    tip = np.stack([np.zeros_like(t), 0.01 * t - 0.05 + 0.02 * d, 0.15 - 0.002 * t + 0.01 * d], axis=-1)
    res = SimpleNamespace(tip_position=tip, axes={"tensions": np.outer(taus, [1.0, 0, 0, 0]), "insertion": depths})
    fig = plotting.plot_fig8b(res)
    (ax,) = fig.axes
    assert ax.get_aspect() == 1.0
    assert len(ax.collections) == 1 and len(ax.collections[0].get_paths()) == 3 * 2  # one cell per grid cell
    assert not any(line.get_linestyle() == "--" for line in ax.get_lines())
    assert "$z_{\\mathrm{tip}}$" in ax.get_xlabel() and "$y_{\\mathrm{tip}}$" in ax.get_ylabel()


def test_fig10_legend_sits_inside_the_innermost_ellipse_and_says_what_is_left_out():
    CMs = {f"{d} mm": np.diag([1e-3, s, 1.1 * s]) for d, s in ((0, 0.2), (50, 0.12), (150, 0.085))}
    fig = plotting.plot_compliance_ellipses(CMs, legend_title="insertion $d$")
    fig.canvas.draw()
    (ax,) = fig.axes
    box = ax.get_legend().get_window_extent().transformed(ax.transData.inverted())
    a, b = 1.1 * 85, 85  # the innermost ellipse's semi-axes [mm/N]
    corners = [(x, y) for x in (box.x0, box.x1) for y in (box.y0, box.y1)]
    assert all((x / a) ** 2 + (y / b) ** 2 < 1 for x, y in corners)
    assert any("\\lambda_1" in t.get_text() and "left out" in t.get_text() for t in fig.texts)


def test_fig16_draws_the_heights_as_discrete_and_shares_the_angle_axis():
    heights, depths = np.array([0.0, 0.02, 0.04]), np.linspace(0, 0.16, 5)
    angle = np.radians(10 + 20 * heights[:, None] / 0.02 + np.sin(depths)[None, :] * 30)
    family = paper.AngleFamily(heights, depths, angle, np.ones_like(angle), np.ones_like(angle, bool))
    fig = plotting.plot_tip_angle_family(family)
    ax, bx = fig.axes
    assert ax.get_ylim() == bx.get_ylim()
    assert not bx.collections  # no filled band between the heights
    assert np.allclose(bx.get_xticks(), heights * 1e3)
    assert "$\\theta_{\\mathrm{tip}}$" in ax.get_ylabel()


def test_stiffness_map_is_against_height_with_one_colour_scale():
    y = np.linspace(-0.04, 0.05, 12).reshape(3, 4)
    m = paper.StiffnessMap(
        tensions=np.arange(3.0),
        insertions=np.arange(4.0),
        z=0.15 + 0 * y,
        y=y,
        least_tension=np.full((3, 4), 0.18),
        stiffest=np.full((3, 4), 0.08),
        insertion_least_tension=np.zeros((3, 4)),
        insertion_stiffest=np.full((3, 4), 0.16),
    )
    fig = plotting.plot_stiffness_map(m)
    colourbars = [a for a in fig.axes if a.get_label() == "<colorbar>"]
    assert len(colourbars) == 1
    assert all("target tip height" in a.get_xlabel() for a in fig.axes if a not in colourbars)


def test_style_is_applied_while_drawing_and_left_behind():
    before = matplotlib.rcParams["font.size"]
    fig = plotting.plot_fig11((0.0, 6.0), (0.0, 0.15), np.ones((2, 2, 3)) * 1e-3)
    assert fig.axes[0].xaxis.label.get_fontsize() == plotting.STYLE["axes.labelsize"]
    assert [a.get_ylabel() for a in fig.axes] == [f"$\\lambda_{k}$ [mm/N]" for k in (1, 2, 3)]
    assert matplotlib.rcParams["font.size"] == before


def test_plot_robot_draws_the_interval_layout_both_sides_of_each_breakpoint():
    """Nodes interval by interval (the tube end and a section end are breakpoints, each node there
    twice): the tube is shaded up to the left side of its end only, each node takes its own side's
    section (the outline steps at a diameter change, nowhere pinched to the centreline), and the
    tendon runs to its anchor."""
    import tdct_jax as tdct

    sections = (
        tdct.Section(end=0.1, outer_diameter=0.02, E=1e6, nu=0.5, density=1e3, inner_diameter=2e-3),
        tdct.Section(end=0.2, outer_diameter=0.01, E=1e6, nu=0.5, density=1e3, inner_diameter=2e-3),
    )
    tube = tdct.Tube(outer_diameter=1.5e-3, inner_diameter=1e-3, E=6e10, nu=0.3, density=6e3)
    robot = tdct.Robot(0.2, sections, (tdct.Tendon(offset=4e-3, angle=0.0),), (tube,))
    s = np.concatenate([np.linspace(0.0, 0.05, 6), np.linspace(0.05, 0.1, 6), np.linspace(0.1, 0.2, 11)])  # d = 50 mm
    assert plotting._starts(s).tolist() == [True] + [False] * 5 + [True] + [False] * 5 + [True] + [False] * 10
    np.testing.assert_array_equal(plotting._tube_mask(s, 0.05), np.arange(len(s)) <= 5)  # the left side of s = d
    sol = SimpleNamespace(
        s=s, position=np.outer(s, [0.0, 0.0, 1.0]), rotation=np.broadcast_to(np.eye(3), (len(s), 3, 3)), tip_angle=0.0
    )
    scene = tdct.Scene((tdct.Plane((0.0, -0.05, 0.0), (0.0, 1.0, 0.0), name="floor"),))
    contact = SimpleNamespace(s=s[:1], position=np.zeros((1, 3)), force=np.zeros((1, 1)), normal=np.zeros((1, 1, 3)))
    contact.active = contact.force > 0
    sol.contact = contact
    fig = plotting.plot_robot(sol, robot, tdct.Actuation((0.0,), 0.05), tdct.Loads(scene=scene))
    side = fig.axes[0]
    (tube_line,) = [line for line in side.get_lines() if "tube 1" in str(line.get_label())]
    assert tube_line.get_xydata()[:, 0].max() == 50.0 and len(tube_line.get_xydata()) == 6
    outline = [line.get_xydata() for line in side.get_lines() if line.get_color() == "0.25"]
    assert len(outline) == 2
    upper = outline[0] if outline[0][:, 1].max() > 0 else outline[1]
    np.testing.assert_allclose(upper[:12, 1], 10.0)  # section 1 to its end, the left side of s = 100 mm
    np.testing.assert_allclose(upper[12:, 1], 5.0)  # section 2 from the right side on
    matplotlib.pyplot.close(fig)


def test_pairs_plot_puts_a_memoryless_model_on_the_axis_and_states_its_share():
    """Equal-servo pairs: a model predicting one tip per pair scores 0 and its points lie at zero
    predicted difference; the measured tips themselves score 1."""
    measured = np.array([[0.0, 0.0, 0.1], [0.003, -0.002, 0.1], [0.01, 0.0, 0.1], [0.012, 0.004, 0.099]])
    pairs = np.array([[0, 1], [2, 3]])
    memoryless = np.array([[0.001, 0.0, 0.1], [0.001, 0.0, 0.1], [0.011, 0.0, 0.1], [0.011, 0.0, 0.1]])
    fig = plotting.plot_pairs(memoryless, measured, pairs)
    ax = fig.axes[0]
    assert "share predicted 0.00" in ax.get_title()
    assert all(np.allclose(line.get_ydata(), 0.0) for line in ax.lines[:3])  # x, y, z: no predicted difference
    assert "share predicted 1.00" in plotting.plot_pairs(measured, measured, pairs).axes[0].get_title()
