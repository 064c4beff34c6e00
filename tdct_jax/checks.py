"""Input checks shared by the pytrees and the entry points: clear errors that name field, value, range."""

from __future__ import annotations

import math
import numbers

import jax
import numpy as np


def is_concrete(x) -> bool:
    """True for values a user passed in; False for tracers (inside jit, vmap, grad) and None."""
    if isinstance(x, jax.core.Tracer):
        return False
    return isinstance(x, (numbers.Number, str, list, tuple, np.ndarray, np.generic, jax.Array))


def as_array(name: str, x, shape: tuple[int, ...] | None = None, *, trailing: tuple[int, ...] | None = None, unit: str = ""):
    """A concrete number or sequence as a finite float64 numpy array; tracers pass unchanged.

    Args:
        name: the field, as the user knows it (for the message).
        x: the value.
        shape: the exact shape required, or None.
        trailing: the shape of the last axes required (leading batch axes allowed), or None.
        unit: appended to the value in messages, e.g. " m".
    """
    if not is_concrete(x):
        return x
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
