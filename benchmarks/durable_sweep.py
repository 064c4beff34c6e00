"""What resumable sweeps cost: ``sweep(out=)``, which saves every chunk to the partial folder
(written, flushed to the disk, renamed) and then assembles the .npz from the chunk files, against
the same sweep kept in memory, timed in turn in one process after a compile; the time spent in
chunk saves and in the assembly; the file's size; peak memory.

Run: python benchmarks/durable_sweep.py [--quick] [--folder DIR]
Writes benchmarks/results/durable_sweep.json (_quick.json with --quick). The files go to a
temporary folder inside DIR (default: the system's temporary folder); fsync costs what the disk
under it costs, so give a folder on the disk a real sweep would write to.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import peak_rss_mb, write_result

import tdct_jax as tdct
from tdct_jax.batch import default_chunk_size, mesh_for
from tdct_jax.checkpoint import Partial


def grid(n_side: int) -> dict:
    return {
        "tensions": np.outer(np.linspace(0.0, 10.0, n_side), [1.0, 0.0, 0.0, 0.0]),
        "insertion": np.linspace(0.0, 0.16, n_side),
        "tip_mass": np.linspace(0.0, 0.05, n_side),
    }


class Clock:
    """Seconds spent in one method of Partial, call by call."""

    def __init__(self, name: str):
        self.calls, method = [], getattr(Partial, name)

        def timed(*args, **kwargs):
            t = time.perf_counter()
            out = method(*args, **kwargs)
            self.calls.append(time.perf_counter() - t)
            return out

        setattr(Partial, name, timed)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="13^3 points and one repeat (default 27^3, three)")
    parser.add_argument("--folder", default=None, help="where the files go (default: the system's temporary folder)")
    args = parser.parse_args()
    n_side, repeats = (13, 1) if args.quick else (27, 3)
    options = dict(grid=grid(n_side), progress=False, throw=False)
    tdct.sweep(**options | dict(grid=grid(4)))  # compiles the default chunk size
    saves, finishes = Clock("save"), Clock("finish")
    memory, streamed, sizes = [], [], []
    with tempfile.TemporaryDirectory(dir=args.folder) as tmp:
        for i in range(repeats):
            t = time.perf_counter()
            res = tdct.sweep(**options)
            memory.append(time.perf_counter() - t)
            t = time.perf_counter()
            path = tdct.sweep(**options, out=Path(tmp) / f"sweep{i}.npz")
            streamed.append(time.perf_counter() - t)
            sizes.append(path.stat().st_size)
        np.testing.assert_array_equal(tdct.gather(path).tip_position, res.tip_position)
    points, chunks = int(np.prod(res.shape)), len(saves.calls) // repeats
    in_memory_s, to_file_s = float(np.median(memory)), float(np.median(streamed))
    result = dict(
        points=points,
        chunk_size=default_chunk_size(mesh_for(None)),
        chunks=chunks,
        repeats=repeats,
        in_memory_s=in_memory_s,
        to_file_s=to_file_s,
        file_over_memory=to_file_s / in_memory_s,
        chunk_save_ms_median=float(np.median(saves.calls)) * 1e3,
        chunk_save_ms_max=float(np.max(saves.calls)) * 1e3,
        chunk_saves_s_per_sweep=float(np.sum(saves.calls)) / repeats,
        assembly_s=float(np.median(finishes.calls)),
        file_mb=sizes[-1] / 1e6,
        failed=res.n_failed,
        peak_rss_mb=peak_rss_mb(),
    )
    for k, v in result.items():
        print(f"{k}: {v:.4g}" if isinstance(v, float) else f"{k}: {v}")
    write_result(Path(__file__).parent / "results" / f"durable_sweep{'_quick' if args.quick else ''}.json", **result)


if __name__ == "__main__":
    main()
