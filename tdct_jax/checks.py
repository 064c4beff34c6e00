"""Input checks shared by the pytrees and the entry points: clear errors that name field, value, range."""

from __future__ import annotations

import contextlib
import math
import numbers
import re
import sys
import tempfile
import tomllib
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .tree import set_fields


def is_concrete(x) -> bool:
    """True for values a user passed in; False for tracers (inside jit, vmap, grad), sequences
    holding one (``(tau, 0.0, 0.0, 0.0)`` with tau traced) and None."""
    if isinstance(x, jax.core.Tracer):
        return False
    if isinstance(x, (list, tuple)):
        return not any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves(x))
    return isinstance(x, (numbers.Number, str, list, tuple, np.ndarray, np.generic, jax.Array))


def array_module(*values):
    """numpy where every value is concrete (building an array from them then costs no JAX dispatch
    per operation), else jax.numpy (some are traced)."""
    return np if all(is_concrete(v) for v in values) else jnp


def as_array(name: str, x, shape: tuple[int, ...] | None = None, *, trailing: tuple[int, ...] | None = None, unit: str = ""):
    """A concrete number or sequence as a finite float64 numpy array; tracers pass unchanged, and a
    sequence holding tracers becomes one traced array.

    Args:
        name: the field, as the user knows it (for the message).
        x: the value.
        shape: the exact shape required, or None.
        trailing: the shape of the last axes required (leading batch axes allowed), or None.
        unit: appended to the value in messages, e.g. " m".
    """
    if not is_concrete(x):
        return jnp.asarray(x, dtype=jnp.float64) if isinstance(x, (list, tuple)) else x
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name} must be numeric, got {x!r}") from e
    if shape is not None and a.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got shape {a.shape} ({x!r})")
    if trailing is not None and (a.ndim < len(trailing) or a.shape[a.ndim - len(trailing) :] != trailing):
        want = "(..., " + ", ".join(map(str, trailing)) + ")"
        raise ValueError(f"{name} must have shape {trailing} (or {want} with leading batch axes), got shape {a.shape} ({x!r})")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got {fmt(a)}{unit}")
    return a


def check_range(name: str, x, lo=-math.inf, hi=math.inf, *, lo_open=False, hi_open=False, unit="", scale=1.0):
    """Raises ValueError unless every element of a concrete x lies in the interval (lo, hi).

    ``scale`` converts x and the bounds for the message only (e.g. 1e3 with unit " mm" for a
    length the user typed in millimetres).
    """
    if not is_concrete(x):
        return
    a = np.asarray(x, dtype=np.float64)
    bad_lo = a <= lo if lo_open else a < lo
    bad_hi = a >= hi if hi_open else a > hi
    if np.any(bad_lo | bad_hi):
        raise ValueError(
            f"{name} = {fmt(a * scale)} is outside the allowed range {interval(lo, hi, lo_open, hi_open, scale)}{unit}"
        )


def check_integer(name: str, x, lo: int = 1) -> int:
    """x as an int, which must be a Python or numpy integer >= lo (no bools, no floats)."""
    if isinstance(x, bool) or not isinstance(x, (int, np.integer)) or x < lo:
        raise ValueError(f"{name} = {x!r} must be an integer >= {lo}")
    return int(x)


def check_iteration(options, tol: str, limit: str, prefix: str = "") -> None:
    """An options pytree's tolerance field ``tol`` (> 0, as a float) and step limit ``limit`` (an
    integer >= 1), each checked and normalised in place where concrete (leaves may be traced)."""
    if is_concrete(getattr(options, tol)):
        value = as_array(prefix + tol, getattr(options, tol), ())
        check_range(prefix + tol, value, 0.0, lo_open=True)
        set_fields(options, **{tol: float(value)})
    if is_concrete(getattr(options, limit)):
        set_fields(options, **{limit: check_integer(prefix + limit, getattr(options, limit))})


def check_choice(name: str, x, choices: tuple) -> None:
    if x not in choices:
        raise ValueError(f"{name} = {x!r} must be one of {choices}")


def interval(lo, hi, lo_open=False, hi_open=False, scale=1.0) -> str:
    """'[lo, hi]' with open ends as parentheses, bounds multiplied by ``scale``."""
    return f"{'(' if lo_open else '['}{num(lo * scale)}, {num(hi * scale)}{')' if hi_open else ']'}"


def num(v: float) -> str:
    return "inf" if v == math.inf else "-inf" if v == -math.inf else f"{v:g}"


def fmt(a) -> str:
    a = np.asarray(a)
    return f"{a.item():g}" if a.ndim == 0 else np.array2string(a, separator=", ")


def check_output(
    name: str, path, folder: bool = False, suffixes: tuple[str, ...] | None = None, kind: str = "a format this output takes"
) -> None:
    """Before any computation: an output file's folder (or an output folder's nearest existing
    ancestor, which it will be made in) exists and takes a new file, and a file's suffix is one of
    ``suffixes`` (lowercase, with the dot; "" allows none) when given, ``kind`` saying what they
    are. A ValueError names the flag (``name`` starting with "-") or the argument (``out =
    '...'``) and the path otherwise."""
    path = Path(path)
    label = f"{name} {path}" if name.startswith("-") else f"{name} = {str(path)!r}"
    if suffixes is not None and path.suffix.lower() not in suffixes:
        allowed = ", ".join(s or "none" for s in suffixes)
        raise ValueError(f"{label}: {path.suffix or 'no suffix'} is not {kind}; allowed: {allowed}")
    if not folder and path.is_dir():
        raise ValueError(f"{label}: is a folder, expected a file name")
    if folder and path.exists() and not path.is_dir():
        raise ValueError(f"{label}: is a file, expected a folder")
    where = path if folder and path.is_dir() else path.parent
    if not folder and not where.is_dir():
        raise ValueError(f"{label}: the folder {where} does not exist")
    while folder and not where.exists():
        where = where.parent
    try:
        with tempfile.TemporaryFile(dir=where):
            pass
        if not folder and path.exists():
            path.open("a").close()
    except OSError as e:
        raise ValueError(f"{label}: cannot write a file in {where} ({e.strerror or e})") from None


class UnitWarning(UserWarning):
    """A value far outside any robot's range, as if typed in another unit: a note, not an error."""


MILLIMETRES = ((1e-3, "millimetres"),)
LENGTHS = ((1e-3, "millimetres"), (1e-2, "centimetres"))
MODULI = ((1e3, "kPa"), (1e6, "MPa"), (1e9, "GPa"))
PLAUSIBLE = {
    # kind: (SI unit, lowest, highest, (lowest, highest) typical, other units it may have been typed in: (1 of them in SI, name))
    "length": ("m", 5e-3, 5.0, (0.02, 1.0), LENGTHS),
    "spacing": ("m", 0.0, 5.0, (1e-3, 0.1), LENGTHS),
    "diameter": ("m", 0.0, 0.5, (1e-4, 0.1), MILLIMETRES),
    "tendon offset": ("m", 0.0, 0.5, (1e-3, 0.1), MILLIMETRES),
    "Young's modulus": ("Pa", 1e3, 1e12, (1e5, 2.5e11), MODULI),  # silicone to steel
    "silicone modulus": ("Pa", 1e3, 1e9, (1e4, 1e8), MODULI),
    "tube modulus": ("Pa", 1e7, 1e12, (1e9, 2.5e11), MODULI),  # polymer to steel
    "density": ("kg/m^3", 100.0, 1e6, (500.0, 2e4), ((1e3, "g/cm^3"),)),  # 1e6: spacer disks lumped into a thin backbone
    "point mass": ("kg", 0.0, 10.0, (1e-4, 1.0), ((1e-3, "grams"),)),
    "angle": ("rad", 0.0, 2 * math.pi, (0.01, 2 * math.pi), ((math.pi / 180, "degrees"),)),
    "twist": ("rad/m", 0.0, 2e3, (1.0, 2e3), ((math.pi / 180, "degrees per metre"),)),
    "tension": ("N", 0.0, 1e4, (0.01, 1e3), ()),
    "axial stiffness": ("N", 1.0, 1e8, (10.0, 1e7), ()),
    "gravity": ("m/s^2", 0.0, 100.0, (1.0, 30.0), ((1e-3, "mm/s^2"),)),
}
"""Magnitudes far outside any TDCT-like robot, by kind of quantity (gravity: the vector's
magnitude): there a value is no error but gets a UnitWarning naming the units it was probably typed
in: those of its other units that make it typical, nearest the typical range's middle (in decades)
first, or else the one that makes it plausible nearest that range. Zero is never flagged. The one
place for these ranges; ``KINDS`` says which fields they apply to."""

KINDS = {
    "Robot": dict(length="length"),
    "Section": dict(
        end=None,  # in (0, length]: the length's note covers it
        outer_diameter="diameter",
        E="Young's modulus",
        nu=None,
        density="density",
        inner_diameter="diameter",
        tendon_channel_diameter="diameter",
        friction=None,
        guide_spacing="spacing",
        damping=None,  # a retardation time: no unit a length or modulus could be mistaken for
    ),
    "Tendon": dict(
        offset="tendon offset", angle="angle", twist="twist", end=None, max_tension="tension", stiffness="axial stiffness"
    ),
    "Tube": dict(outer_diameter="diameter", inner_diameter="diameter", E="tube modulus", nu=None, density="density"),
    "PointMass": dict(s=None, mass="point mass"),
    "paper": dict(  # Robot.paper's Table II names
        length=None,  # the Robot's own note
        outer_diameter="diameter",
        channel_diameter="diameter",
        tendon_offset="tendon offset",
        tendon_angles="angle",
        tendon_channel_diameter="diameter",
        E_silicone="silicone modulus",
        nu_silicone=None,
        density_silicone="density",
        tube_outer_diameter="diameter",
        tube_inner_diameter="diameter",
        E_tube="tube modulus",
        nu_tube=None,
        density_tube="density",
        calibrated_tension=None,
        calibrated_tip_force=None,
    ),
}
"""The kind (``PLAUSIBLE``) of every field of the robot's classes and of ``Robot.paper``'s names;
None: no unit to mistake (a ratio), a place in [0, length] (the length's note covers it), or a
calibrated range."""


TARGET_REACH = (0.01, 10.0)
"""Distances from the base, in robot lengths, outside which (but for 0) a tip target, a recorded
tip or an obstacle was probably typed in another unit: no tip gets there (a note, not an error;
the IK answers with the nearest pose)."""


def reach_note(name: str, distance, length: float, typed_in_mm: bool = False, mean: bool = False) -> str | None:
    """A note for distances [m] from the base (any shape) of which the largest (``mean``: their
    mean) lies farther than ``TARGET_REACH`` robot lengths, as if typed in millimetres, or, for
    values typed in millimetres (``typed_in_mm``), the smallest non-zero one (``mean``: their mean)
    nearer than its lower end, as if typed in metres; None otherwise."""
    d = np.ravel(np.asarray(distance, dtype=float))
    lo, hi = TARGET_REACH
    far = d.mean() if mean else d.max()
    near = d.mean() if mean else d[d > 0].min(initial=np.inf)
    if not typed_in_mm and far > hi * length:
        return (
            f"{name}: {far:g} m from the base is {far / length:.3g} robot lengths away, where no tip reaches: "
            f"positions are in metres; did you mean millimetres ({far / 1e3:g} m)?"
        )
    if typed_in_mm and 0 < near < lo * length:
        return (
            f"{name}: {1e3 * near:g} mm from the base is {near / length:.2g} robot lengths away: "
            f"did you type metres ({1e6 * near:g} mm)?"
        )
    return None


def target_note(name: str, position, length: float, typed_in_mm: bool = False) -> str | None:
    """``reach_note`` for tip target(s) ``position`` [m] (the counted components; any leading axes)."""
    return reach_note(name, np.linalg.norm(np.atleast_2d(np.asarray(position, dtype=float)), axis=-1), length, typed_in_mm)


def plausibility_note(kind: str, value, label: str) -> str | None:
    """A note for a concrete value (any shape: its first offending element) whose magnitude lies
    far outside ``PLAUSIBLE[kind]``, naming the units it was probably typed in; None when
    plausible, zero, traced or None."""
    if value is None or not is_concrete(value):
        return None
    a = np.abs(np.ravel(np.asarray(value, dtype=float)))
    unit, lo, hi, (low, high), others = PLAUSIBLE[kind]
    bad = np.flatnonzero((a != 0) & ((a < lo) | (a > hi)))
    if not bad.size:
        return None
    v = float(a[bad[0]])
    label = label if np.ndim(value) == 0 else f"{label}[{bad[0]}]"
    text = f"{label} = {v:g} {unit} is far outside the plausible range [{lo:g}, {hi:g}] {unit}"
    middle = math.log10(low * high) / 2
    fits = sorted((abs(math.log10(v * f) - middle), low <= v * f <= high, f, u) for f, u in others if lo <= v * f <= hi)
    if not fits:
        return f"{text}: check its unit (SI)"
    named = [(f, u) for _, typical, f, u in fits if typical] or [fits[0][2:]]
    guesses = [f"{v:g} {u} ({v * f:g} {unit})" for f, u in named]
    said = guesses[0] if len(guesses) == 1 else f"{', '.join(guesses[:-1])} or {guesses[-1]}"
    return f"{text}: did you mean {said}?"


def warn_implausible(what: str, values, prefix: str = "") -> None:
    """UnitWarnings (``plausibility_note``) for the fields of ``what`` (a key of ``KINDS``) in
    ``values`` (an object, or a dict by name), each labelled ``prefix`` + its name."""
    for name, kind in KINDS[what].items():
        value = values[name] if isinstance(values, dict) else getattr(values, name)
        note = kind and plausibility_note(kind, value, prefix + name)
        if note:
            warn_user(note, UnitWarning)


def size_note(length, sizes: dict) -> str | None:
    """A note when the largest of ``sizes`` (label: a tendon offset or a diameter [m], concrete)
    exceeds the robot's ``length`` [m]: one of them was probably typed in another unit."""
    label, v = max(((k, float(x)) for k, x in sizes.items()), key=lambda kv: kv[1], default=("", 0.0))
    if not v > float(length):
        return None
    return (
        f"{label} = {v:g} m is larger than the robot's length = {float(length):g} m: is one of them in another unit (SI: metres)?"
    )


def merged(notes: list[str]) -> list[str]:
    """Notes that differ only in the item they name (``tendons[0].offset = 10 m ...``,
    ``tendons[1].offset = 10 m ...``) as one naming the items as a range (``tendons[0-1].offset
    = 10 m ...``), in the order first seen."""
    groups: dict[str, dict] = {}
    for note in notes:
        label, _, rest = note.partition(" = ")
        m = re.fullmatch(r"(\w+)\[(\d+)\]\.(\w+)", label)
        key = (m[1], m[3]) if m else (label, None)
        groups.setdefault(rest, {}).setdefault(key, []).append(int(m[2]) if m else None)
    out = []
    for rest, labels in groups.items():
        names = []
        for (kind, field), index in labels.items():
            if field is None:
                names.append(kind)
                continue
            runs = np.split(np.asarray(index), np.flatnonzero(np.diff(index) != 1) + 1)
            names += [f"{kind}[{r[0]}{'' if len(r) == 1 else f'-{r[-1]}'}].{field}" for r in runs]
        out.append(f"{', '.join(names)} = {rest}")
    return out


@contextlib.contextmanager
def relabelled_notes(relabel=str):
    """UnitWarnings raised inside, ``merged`` and warned again with ``relabel(note)`` as their text
    (attributed to the caller's code) when the block ends without an error; other warnings pass."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UnitWarning)
        yield
    for w in caught:
        if not issubclass(w.category, UnitWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    for note in merged([str(w.message) for w in caught if issubclass(w.category, UnitWarning)]):
        warn_user(relabel(note), UnitWarning)


def warn_user(message: str, category=UserWarning) -> None:
    """``warnings.warn`` attributed to the first caller outside tdct_jax (and the contextlib and
    dataclasses code it runs through)."""
    level, frame = 2, sys._getframe(1)
    while frame is not None and frame.f_globals.get("__name__", "").startswith(("tdct_jax", "contextlib", "dataclasses")):
        frame, level = frame.f_back, level + 1
    warnings.warn(message, category, stacklevel=level)


def read_toml(path, what: str) -> dict:
    """The top-level table of a TOML file; a ValueError "cannot read {what} {path}: ..." when the
    file cannot be read or parsed."""
    path = Path(path)
    try:
        return tomllib.loads(path.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise ValueError(f"cannot read {what} {path}: {e}") from None


_DEPRECATED: set[str] = set()


def deprecated(old: str, new: str) -> None:
    """A FutureWarning, once per process for each ``old`` name, that says what to write instead."""
    if old in _DEPRECATED:
        return
    _DEPRECATED.add(old)
    warn_user(f"{old} is deprecated and will be removed: write {new} (CHANGELOG.md)", FutureWarning)
