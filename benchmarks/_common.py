"""Shared by the benchmark scripts: timing with block_until_ready, and results files that say
when, where and with which JAX they were measured."""

from __future__ import annotations

import json
import platform
import resource
import time
from pathlib import Path

import jax
import numpy as np


def timings(f, repeats: int) -> np.ndarray:
    """Wall-clock seconds of ``repeats`` warm calls of f (each waited for with block_until_ready)."""
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(f())
        times.append(time.perf_counter() - t)
    return np.array(times)


def peak_rss_mb() -> float:
    """This process's peak resident memory so far [MB] (Linux reports ru_maxrss in KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def write_result(path: str | Path, **fields) -> None:
    """Writes fields as JSON, after the date, the machine and the JAX version."""
    result = dict(
        date=time.strftime("%Y-%m-%d"),
        machine=f"{platform.processor() or platform.machine()}, {jax.device_count()} x {jax.devices()[0].platform}",
        jax=jax.__version__,
        **fields,
    )
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(json.dumps(result, indent=2) + "\n")
