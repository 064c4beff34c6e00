"""`tdct reproduce --quick`: every figure and the summary are written, each headline beside the paper."""

import json

import pytest

from tdct_jax.cli import main

FIGURES = {
    "fig8a_shapes.png",
    "fig8b_workspace.png",
    "fig9_tip_pose.png",
    "fig10_compliance_ellipses.png",
    "fig11_compliance_eigenvalues.png",
    "fig13_optimal_insertion.png",
    "fig14_load_capacity.png",
    "fig16_tip_angle_redundancy.png",
}


@pytest.mark.slow
def test_quick_reproduce_writes_every_figure_and_the_summary(tmp_path, capsys):
    assert main(["reproduce", "--quick", "--quiet", "--out", str(tmp_path)]) == 0
    assert FIGURES <= {p.name for p in tmp_path.glob("*.png")}
    assert all((tmp_path / f).stat().st_size > 20_000 for f in FIGURES)
    summary = json.loads((tmp_path / "summary.json").read_text())
    rows = summary["headlines"]
    assert sum(r["quantity"] == "load capacity" for r in rows) == 10
    assert {"optimal insertion", "compliance reduction by the tube", "largest bending angle"} <= {r["quantity"] for r in rows}
    for r in rows:
        if r["paper"] is None:  # a study the paper shows without a number (Sec. V.B's tip-angle range)
            assert r["relative_difference"] is None and r["model"] is not None
        else:
            assert abs(r["relative_difference"] - (r["model"] - r["paper"]) / abs(r["paper"])) < 1e-12
        assert "NOT" not in r["note"]
    assert sum(r["paper"] is not None for r in rows) >= 14
    assert summary["total_seconds"] > 0
    text = capsys.readouterr().out
    assert "| load capacity |" in text and "Total time" in text
