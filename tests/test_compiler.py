"""``import tdct_jax`` adds the fast-compile XLA flag, and leaves a user's choice alone."""

import os
import subprocess
import sys

import jaxlib
import pytest

from tdct_jax.compiler import FAST_COMPILE, TESTED_JAXLIB

PRINT_FLAGS = "import os, tdct_jax; print(os.environ.get('XLA_FLAGS', ''))"


def flags_after_import(**env) -> str:
    clean = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "TDCT_FAST_COMPILE")}
    out = subprocess.run([sys.executable, "-c", PRINT_FLAGS], env=clean | env, capture_output=True, text=True, check=True)
    return out.stdout.strip()


@pytest.mark.skipif(not jaxlib.__version__.startswith(TESTED_JAXLIB), reason="the flag is set only on tested jaxlibs")
def test_import_adds_the_flag_after_the_users_own():
    assert flags_after_import() == FAST_COMPILE
    assert flags_after_import(XLA_FLAGS="--xla_cpu_enable_fast_math=false") == f"--xla_cpu_enable_fast_math=false {FAST_COMPILE}"


def test_a_users_setting_or_opt_out_wins():
    assert flags_after_import(XLA_FLAGS="--xla_cpu_use_fusion_emitters=true") == "--xla_cpu_use_fusion_emitters=true"
    assert flags_after_import(TDCT_FAST_COMPILE="0") == ""
