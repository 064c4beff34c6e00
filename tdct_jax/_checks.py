"""Input checks shared by the pytrees and the solver: clear errors that name field, value, range."""

from __future__ import annotations

import math
import numbers

import jax
import numpy as np


def is_concrete(x) -> bool:
    """True for values a user passed in; False for tracers and the placeholders pytrees carry
    (None, object(), jax's argument descriptions when lowering)."""
    if isinstance(x, jax.core.Tracer):
        return False
    return isinstance(x, (numbers.Number, str, list, tuple, np.ndarray, np.generic, jax.Array))


def as_array(name: str, x, shape: tuple[int, ...] | None = None):
    """Converts a concrete number or sequence to a float64 numpy array of the given shape."""
    if not is_concrete(x):
        return x
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name} must be numeric, got {x!r}") from e
    if shape is not None and a.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got shape {a.shape} ({x!r})")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got {_fmt(a)}")
    return a


def check_range(name: str, x, lo=-math.inf, hi=math.inf, *, lo_open=False, hi_open=False, unit=""):
    """Raises ValueError unless every element of a concrete x lies in the interval (lo, hi)."""
    if not is_concrete(x):
        return
    a = np.asarray(x, dtype=np.float64)
    bad_lo = a <= lo if lo_open else a < lo
    bad_hi = a >= hi if hi_open else a > hi
    if np.any(bad_lo | bad_hi):
        interval = f"{'(' if lo_open else '['}{_num(lo)}, {_num(hi)}{')' if hi_open else ']'}"
        raise ValueError(f"{name} = {_fmt(a)} is outside the allowed range {interval}{unit}")


def _num(v: float) -> str:
    return "inf" if v == math.inf else "-inf" if v == -math.inf else f"{v:g}"


def _fmt(a: np.ndarray) -> str:
    return f"{a.item():g}" if a.ndim == 0 else np.array2string(a, separator=", ")
