"""Input checks shared by the pytrees and the entry points: clear errors that name field, value, range."""

from __future__ import annotations

import math
import numbers
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
PLAUSIBLE = {
    # name: (SI unit, lowest, highest, typical, other units it may have been typed in: (1 of them in SI, name))
    "length": ("m", 5e-3, 5.0, 0.16, ((1e-3, "millimetres"), (1e-2, "centimetres"))),
    "outer_diameter": ("m", 0.0, 0.5, 0.02, MILLIMETRES),
    "channel_diameter": ("m", 0.0, 0.5, 1.5e-3, MILLIMETRES),
    "tendon_offset": ("m", 0.0, 0.5, 7e-3, MILLIMETRES),
    "tendon_channel_diameter": ("m", 0.0, 0.5, 1e-3, MILLIMETRES),
    "tube_outer_diameter": ("m", 0.0, 0.5, 1.4e-3, MILLIMETRES),
    "tube_inner_diameter": ("m", 0.0, 0.5, 1.1e-3, MILLIMETRES),
    "E_silicone": ("Pa", 1e3, 1e9, 1e6, ((1e6, "MPa"), (1e9, "GPa"), (1e3, "kPa"))),
    "E_tube": ("Pa", 1e7, 1e12, 1e11, ((1e6, "MPa"), (1e9, "GPa"), (1e3, "kPa"))),
    "density_silicone": ("kg/m^3", 100.0, 3e4, 1500.0, ((1e3, "g/cm^3"),)),
    "density_tube": ("kg/m^3", 100.0, 3e4, 6500.0, ((1e3, "g/cm^3"),)),
    "gravity": ("m/s^2", 0.0, 100.0, 9.81, ((1e-3, "mm/s^2"),)),
}
"""Magnitudes far outside any TDCT-like robot, by field (gravity: the vector's magnitude): there a
value is no error but gets a UnitWarning naming the unit it was probably typed in (of several that
would make it plausible, the one that lands nearest the typical value, in decades). Zero is never
flagged. The one place for these ranges."""


TARGET_REACH = (0.01, 10.0)
"""Distances of a tip target from the base, in robot lengths, outside which (but for 0) a target was
probably typed in another unit: no tip gets there (a note, not an error; the IK answers with the
nearest pose)."""


def target_note(name: str, position, length: float, typed_in_mm: bool = False) -> str | None:
    """A note for tip target(s) ``position`` [m] (the counted components; any leading axes) that
    lie farther than ``TARGET_REACH`` robot lengths from the base, as if typed in millimetres, or,
    for values typed in millimetres (``typed_in_mm``), nearer than its lower end, as if typed in
    metres; None otherwise."""
    d = np.linalg.norm(np.atleast_2d(np.asarray(position, dtype=float)), axis=-1)
    lo, hi = TARGET_REACH
    far, near = d.max() / length, d[d > 0].min(initial=np.inf) / length
    if not typed_in_mm and far > hi:
        return (
            f"{name}: {d.max():g} m from the base is {far:.3g} robot lengths away, where no tip reaches: "
            f"positions are in metres; did you mean millimetres ({d.max() / 1e3:g} m)?"
        )
    if typed_in_mm and near < lo:
        return (
            f"{name}: {1e3 * near * length:g} mm from the base is {near:.2g} robot lengths away: "
            f"did you type metres ({1e6 * near * length:g} mm)?"
        )
    return None


def plausibility_note(name: str, value, label: str | None = None) -> str | None:
    """A note for a concrete scalar whose magnitude lies far outside ``PLAUSIBLE[name]``, naming
    the unit it was probably typed in (and the value as ``label``, default ``name``); None when
    plausible, zero, traced or not in the table."""
    if name not in PLAUSIBLE or not is_concrete(value) or np.size(value) != 1:
        return None
    v = abs(float(np.asarray(value, dtype=float).ravel()[0]))
    unit, lo, hi, typical, others = PLAUSIBLE[name]
    if v == 0.0 or lo <= v <= hi:
        return None
    fits = [(abs(math.log10(v * f / typical)), f, u) for f, u in others if lo <= v * f <= hi]
    text = f"{label or name} = {v:g} {unit} is far outside the plausible range [{lo:g}, {hi:g}] {unit}"
    if not fits:
        return f"{text}: check its unit (SI)"
    _, factor, other = min(fits)
    return f"{text}: did you mean {v:g} {other} ({v * factor:g} {unit})?"


def warn_user(message: str, category=UserWarning) -> None:
    """``warnings.warn`` attributed to the first caller outside tdct_jax."""
    level, frame = 2, sys._getframe(1)
    while frame is not None and frame.f_globals.get("__name__", "").startswith("tdct_jax"):
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
