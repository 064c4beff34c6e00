"""XLA:CPU compiler flags that shorten compiles, set before JAX starts its backends (no physics)."""

from __future__ import annotations

import os

FAST_COMPILE = "--xla_cpu_use_fusion_emitters=false"
"""XLA:CPU's older fusion code generator: on the 2-core machine a cold forward solve compiles in
3.7 s instead of 4.4 s and an IK plan in 8.2 s instead of 10.4 s, the compiled programs as fast
(docs/performance.md, "Compiling"). XLA aborts the process on a flag it does not know, so it is set
only for the jaxlib versions it was measured on."""

TESTED_JAXLIB = ("0.10.",)


def use_fast_compile_flags() -> bool:
    """Adds FAST_COMPILE to XLA_FLAGS unless the user set that flag, TDCT_FAST_COMPILE is "0", or the
    installed jaxlib is not one of TESTED_JAXLIB. Takes effect only before JAX first computes
    anything (``import tdct_jax`` calls it first); returns whether it added the flag."""
    import jaxlib

    flags = os.environ.get("XLA_FLAGS", "")
    if (
        os.environ.get("TDCT_FAST_COMPILE", "1") == "0"
        or "xla_cpu_use_fusion_emitters" in flags
        or not jaxlib.__version__.startswith(TESTED_JAXLIB)
    ):
        return False
    os.environ["XLA_FLAGS"] = f"{flags} {FAST_COMPILE}".strip()
    return True
