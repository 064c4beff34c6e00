"""Robot description (paper Table II), derived section properties and stiffness matrices."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .checks import UnitWarning, as_array, check_range, fmt, interval, is_concrete, plausibility_note, read_toml, warn_user
from .description import GeneralRobot, channelled_area, channelled_second_moments, from_paper
from .tree import pytree, set_fields, static

SCALAR_FIELDS = (
    "length",
    "outer_diameter",
    "channel_diameter",
    "tendon_offset",
    "tendon_channel_diameter",
    "E_silicone",
    "nu_silicone",
    "density_silicone",
    "tube_outer_diameter",
    "tube_inner_diameter",
    "E_tube",
    "nu_tube",
    "density_tube",
)
UNITS = dict(E_silicone=" Pa", E_tube=" Pa", density_silicone=" kg/m^3", density_tube=" kg/m^3", nu_silicone="", nu_tube="")
"""Units of the scalar fields in messages (lengths: m)."""


class CalibrationWarning(UserWarning):
    """Inputs outside the range a robot was calibrated over: a note, not an error."""


@pytree
class Robot:
    """Geometry and materials of the TDCT robot, SI units; every field is a differentiable leaf.

    Defaults are the paper's Table II. The paper gives neither the tendon offset nor the silicone
    density: ``tendon_offset`` and ``density_silicone`` are fitted (``paper.fit_load_capacities``,
    Gauss-Newton on exact derivatives) to the ten load capacities of Sec. V.A. One offset alone
    cannot match them (16% rms misfit); the pair leaves 5.7% rms. The fitted density is above the
    1130 kg/m^3 of Elastosil M4601: it is an effective one that also carries what the model leaves
    out (tendons, sensor fibre, tip fixture). The tendon channel diameter is a guess and the tube
    density a handbook value for Nitinol.

    Attributes:
        length: robot length L [m].
        outer_diameter: silicone body diameter [m].
        channel_diameter: central channel the tube slides in [m].
        tendon_offset: tendon radius r_t from the axis [m].
        tendon_angles: tendon positions about +z from body +x [rad], shape (n_tendons,).
            Default: tendon 1 at +y, then counter-clockwise in 90 degree steps.
        tendon_channel_diameter: diameter of each tendon channel [m].
        E_silicone: silicone Young's modulus [Pa].
        nu_silicone: silicone Poisson ratio.
        density_silicone: silicone density [kg/m^3].
        tube_outer_diameter: outer diameter of the Nitinol tube [m].
        tube_inner_diameter: inner diameter of the Nitinol tube [m].
        E_tube: tube Young's modulus [Pa].
        nu_tube: tube Poisson ratio.
        density_tube: tube density [kg/m^3].
        calibrated_tension: (lowest, highest) tension [N] the model was calibrated over (static);
            inputs beyond it get a CalibrationWarning, not an error. Default the paper's 0-10 N.
        calibrated_tip_force: (lowest, highest) tip force magnitude [N] likewise (static);
            default the paper's 0-0.5 N (50 g).
    """

    length: float = 0.160
    outer_diameter: float = 0.020
    channel_diameter: float = 1.5e-3
    tendon_offset: float = 6.931e-3  # fitted to Sec. V.A load capacities (see above)
    tendon_angles: tuple = (np.pi / 2, np.pi, 3 * np.pi / 2, 0.0)
    tendon_channel_diameter: float = 1.0e-3
    E_silicone: float = 0.85e6
    nu_silicone: float = 0.5
    density_silicone: float = 1792.0  # effective, fitted with tendon_offset (see above)
    tube_outer_diameter: float = 1.397e-3
    tube_inner_diameter: float = 1.118e-3
    E_tube: float = 83e9
    nu_tube: float = 0.33
    density_tube: float = 6450.0
    calibrated_tension: tuple = static(default=(0.0, 10.0))
    calibrated_tip_force: tuple = static(default=(0.0, 0.5))

    def __post_init__(self):
        set_fields(self, **{name: as_array(name, getattr(self, name), (), unit=_unit(name)) for name in SCALAR_FIELDS})
        for name in ("calibrated_tension", "calibrated_tip_force"):
            bounds = as_array(name, getattr(self, name), (2,), unit=" N")
            check_range(name, bounds, 0.0, unit=" N")
            if bounds[0] > bounds[1]:
                raise ValueError(f"{name} = {fmt(bounds)} N must be (lowest, highest) with lowest <= highest")
            set_fields(self, **{name: tuple(float(b) for b in bounds)})
        angles = self.tendon_angles
        if is_concrete(angles):
            n = np.asarray(angles).size
            angles = as_array("tendon_angles", angles, (n,))
            if n == 0:
                raise ValueError("tendon_angles must list at least one tendon, got an empty list")
        set_fields(self, tendon_angles=angles)
        self._check()
        for name in SCALAR_FIELDS:
            note = plausibility_note(name, getattr(self, name))
            if note:
                warn_user(note, UnitWarning)

    def _check(self):
        for name in ("length", "outer_diameter", "E_silicone", "E_tube", "tube_outer_diameter"):
            check_range(name, getattr(self, name), 0.0, lo_open=True, unit=_unit(name))
        for name in ("density_silicone", "density_tube", "tendon_channel_diameter", "tube_inner_diameter"):
            check_range(name, getattr(self, name), 0.0, unit=_unit(name))
        for name in ("nu_silicone", "nu_tube"):
            check_range(name, getattr(self, name), -1.0, 0.5, lo_open=True)
        if not all(is_concrete(getattr(self, f.name)) for f in dataclasses.fields(self)):
            return
        check_range("channel_diameter", self.channel_diameter, 0.0, self.outer_diameter, hi_open=True, unit=" m")
        check_range(
            "tube_outer_diameter",
            self.tube_outer_diameter,
            0.0,
            self.channel_diameter,
            lo_open=True,
            unit=" m (must fit the channel)",
        )
        check_range("tube_inner_diameter", self.tube_inner_diameter, 0.0, self.tube_outer_diameter, hi_open=True, unit=" m")
        dt = float(self.tendon_channel_diameter)
        rim = (float(self.outer_diameter) - dt) / 2
        if dt > 0:  # a channel of its own: outside the central channel and inside the body
            core = (float(self.channel_diameter) + dt) / 2
            where = " m (tendon channels between the central channel and the surface)"
            check_range("tendon_offset", self.tendon_offset, core, rim, unit=where)
            self._check_tendon_spacing(dt)
        else:
            check_range("tendon_offset", self.tendon_offset, 0.0, rim, unit=" m (tendons inside the body)")
        if float(self.area_silicone) <= 0:
            raise ValueError(
                f"the silicone cross-section area {float(self.area_silicone):g} m^2 is not positive: channels larger than the body"
            )

    def _check_tendon_spacing(self, dt: float) -> None:
        """Tendon channels of diameter dt at radius r_t do not overlap each other."""
        a = np.asarray(self.tendon_angles)
        if a.size < 2:
            return
        gap = np.abs((a[:, None] - a[None, :] + np.pi) % (2 * np.pi) - np.pi)
        np.fill_diagonal(gap, np.inf)
        i, j = np.unravel_index(np.argmin(gap), gap.shape)
        distance = 2 * float(self.tendon_offset) * np.sin(gap[i, j] / 2)
        if distance <= dt:
            raise ValueError(
                f"tendon_angles: tendons {min(i, j) + 1} and {max(i, j) + 1} are {np.degrees(gap[i, j]):.3g} deg apart, so their "
                f"channels (diameter {dt:g} m) at tendon_offset {float(self.tendon_offset):g} m overlap: centres {distance:.3g} m "
                f"apart, at least {dt:g} m needed"
            )

    def calibration_notes(self, tensions, tip_force) -> list[str]:
        """Notes for concrete inputs outside the calibrated ranges (tensions [N], tip forces [N],
        any leading axes); tracers give none."""
        notes = []
        magnitudes = None if not is_concrete(tip_force) else np.linalg.norm(np.asarray(tip_force, dtype=float), axis=-1)
        for what, values, (lo, hi) in (
            ("tensions", tensions, self.calibrated_tension),
            ("tip force magnitudes", magnitudes, self.calibrated_tip_force),
        ):
            if values is None or not is_concrete(values) or np.size(values) == 0:
                continue
            v = np.asarray(values, dtype=float)
            extreme = f"up to {v.max():.4g} N" if v.max() > hi else f"down to {v.min():.4g} N" if v.min() < lo else None
            if extreme:
                notes.append(
                    f"{what} {extreme} are outside the range {interval(lo, hi)} N this robot was calibrated over: "
                    "the model is not validated there (far above it, shapes may loop)"
                )
        return notes

    def warn_outside_calibration(self, tensions, tip_force) -> None:
        """``calibration_notes`` as CalibrationWarnings, attributed to the caller's code."""
        for note in self.calibration_notes(tensions, tip_force):
            warn_user(note, CalibrationWarning)

    @classmethod
    def from_toml(cls, path: str | Path) -> Robot:
        """Reads a robot from a TOML file of Robot field names in SI units (missing ones default).

        A file with ``[[sections]]`` is the general robot file (docs/robot-file.md): it gives a
        ``tdct.GeneralRobot`` (``GeneralRobot.from_toml``).

        Raises:
            ValueError: the file cannot be read or parsed, has unknown keys or bad values.
        """
        path = Path(path)
        data = read_toml(path, "robot file")
        if "sections" in data:
            return GeneralRobot.from_table(data, path)
        data = data.get("robot", data)
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"robot file {path}: unknown field(s) {unknown}; allowed: {sorted(known)}")
        with warnings.catch_warnings(record=True) as notes:
            warnings.simplefilter("always", UnitWarning)
            try:
                robot = cls(**data)
            except ValueError as e:
                raise ValueError(f"robot file {path}: {e}") from e
        for note in notes:
            if issubclass(note.category, UnitWarning):
                warn_user(f"robot file {path}: {note.message}", UnitWarning)
            else:
                warnings.warn_explicit(note.message, note.category, note.filename, note.lineno)
        return robot

    def to_general(self):
        """This robot as a ``tdct.GeneralRobot`` (one section, tendons at the tip, one tube whose
        depth is the actuation's insertion): ``tdct.solve`` gives the same results for both
        (within 1e-12 relative). ``Robot`` keeps its own fields and solver path, used by
        calibration, sweeps, the CLI and the paper studies."""
        return from_paper(self)

    @property
    def n_tendons(self) -> int:
        return int(np.shape(self.tendon_angles)[0])

    @property
    def tendon_positions(self):
        """Body-frame tendon offsets r_t, shape (n_tendons, 3) [m]."""
        a = jnp.asarray(self.tendon_angles)
        return self.tendon_offset * jnp.stack([jnp.cos(a), jnp.sin(a), jnp.zeros_like(a)], axis=-1)

    @property
    def area_silicone(self):
        """Silicone area A1: outer disc minus tube channel and tendon channels [m^2]."""
        return channelled_area(self.outer_diameter, self.channel_diameter, self.tendon_channel_diameter, self.n_tendons)

    @property
    def second_moments_silicone(self):
        """(I_x, I_y) of the silicone section, tendon channels by the parallel-axis theorem [m^4]."""
        return channelled_second_moments(
            self.outer_diameter, self.channel_diameter, self.tendon_channel_diameter, self.tendon_positions, 1.0
        )

    @property
    def area_tube(self):
        return jnp.pi / 4 * (self.tube_outer_diameter**2 - self.tube_inner_diameter**2)

    @property
    def second_moment_tube(self):
        return jnp.pi / 64 * (self.tube_outer_diameter**4 - self.tube_inner_diameter**4)

    @property
    def G_silicone(self):
        return self.E_silicone / (2 * (1 + self.nu_silicone))

    def shear_stiffness(self):
        """K_se = diag(G1 A1, G1 A1, E1 A1) of the silicone [N] (docs/model.md)."""
        A = self.area_silicone
        return jnp.stack([self.G_silicone * A, self.G_silicone * A, self.E_silicone * A])

    def bending_stiffness(self, with_tube: bool):
        """K_bt diagonal [N m^2]: diag(E1 I1, E1 I1, G1 J1), plus E2 I2 in bending with the tube (eq. 30)."""
        I_x, I_y = self.second_moments_silicone
        extra = self.E_tube * self.second_moment_tube if with_tube else 0.0
        return jnp.stack([self.E_silicone * I_x + extra, self.E_silicone * I_y + extra, self.G_silicone * (I_x + I_y)])

    @property
    def tube_linear_density(self):
        """Mass per unit length of the Nitinol tube [kg/m]."""
        return self.density_tube * self.area_tube

    def linear_density(self, with_tube: bool):
        """Mass per unit length [kg/m] of the silicone, plus the tube where it is inserted."""
        rho = self.density_silicone * self.area_silicone
        return rho + self.tube_linear_density if with_tube else rho


def _unit(name: str) -> str:
    return UNITS.get(name, " m")
