"""Robot fields by name (fields.py): the names sweeps, calibrations and --set share."""

import re

import jax
import pytest

import tdct_jax as tdct
from tdct_jax import fields
from tdct_jax.description import ROBOTS


@pytest.fixture(scope="module")
def two():
    return tdct.Robot.from_toml(ROBOTS / "two_segment.toml")


def test_item_fields_by_position_and_shared(two):
    changed = fields.replace(two, {"sections[*].E": 60e9, "tendons[4].offset": 0.012, "length": 0.4})
    assert [float(s.E) for s in changed.sections] == [60e9, 60e9]
    assert float(changed.tendons[4].offset) == 0.012 and float(changed.tendons[3].offset) == 0.010
    assert fields.value(changed, "sections[*].E") == 60e9
    assert fields.value(two, "tendons[1].angle") == pytest.approx(-0.5235987755982988)
    assert len(fields.names(two)) == 1 + 2 * 10 + 6 * 6
    assert fields.names(tdct.Robot.paper())[0] == "length" and fields.is_linear("tendons[0].angle")
    assert not fields.is_linear("sections[0].E")


def test_traced_values_pass_through(two):
    E = jax.jit(lambda E: fields.replace(two, {"sections[*].E": E}).sections[1].E)(3.0)
    assert float(E) == 3.0
    assert float(fields.replace(tdct.Robot.paper(), {"sections[*].E": 1e5}).sections[0].E) == 1e5


def test_a_range_shares_one_value_among_its_items(two):
    robot = fields.replace(two, {"tendons[1-3].offset": 0.012})
    assert [float(t.offset) for t in robot.tendons] == [0.010, 0.012, 0.012, 0.012, 0.010, 0.010]
    assert fields.value(robot, "tendons[1-3].offset") == 0.012
    with pytest.raises(ValueError, match="values differ"):
        fields.value(robot, "tendons[0-1].offset")
    with pytest.raises(ValueError, match=re.escape("6 tendons (indices 0 to 5, or a range a-b with a <= b)")):
        fields.check(two, "tendons[4-6].offset")
    with pytest.raises(ValueError, match="a <= b"):
        fields.check(two, "tendons[3-1].offset")


@pytest.mark.parametrize(
    "name, words",
    [
        ("sections[2].E", "2 sections (indices 0 to 1, or a range a-b with a <= b)"),
        ("tendon[0].offset", "not a scalar robot field"),
        ("tendons[0].radius", "tendons[i, * or a-b].{offset, angle"),
        ("E_robot", "not a scalar robot field"),
    ],
)
def test_unknown_names_say_what_exists(two, name, words):
    with pytest.raises(ValueError, match=re.escape(words)):
        fields.check(two, name)


def test_bad_values_name_the_item(two):
    with pytest.raises(ValueError, match=r"sections\[1\]\.E = -1 is outside"):
        fields.replace(two, {"sections[1].E": -1.0})
    with pytest.raises(ValueError, match=r"tendons\[0\]\.stiffness is not set"):
        fields.value(two, "tendons[0].stiffness")
    with pytest.raises(ValueError, match="values differ"):
        fields.value(fields.replace(two, {"tendons[0].offset": 0.011}), "tendons[*].offset")
    with pytest.raises(ValueError, match=re.escape("1 sections (indices 0 to 0")):
        fields.check(tdct.Robot.paper(), "sections[1].E")


def test_the_paper_robots_former_names_resolve_with_a_warning(two, monkeypatch):
    """ "E_silicone" and its kin name the one description's fields, on any robot, warning once."""
    monkeypatch.setattr(tdct.checks, "_DEPRECATED", set())  # as in a fresh process
    with pytest.warns(FutureWarning, match="'sections\\[\\*\\].E'"):
        changed = fields.replace(two, {"E_silicone": 2e6})
    assert [float(s.E) for s in changed.sections] == [2e6, 2e6]
    assert fields.PAPER_NAMES["tendon_offset"] == "tendons[*].offset"
