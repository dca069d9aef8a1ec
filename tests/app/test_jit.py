"""app.jit: numba's CPU target gets 512-bit vectors on AVX-512 hosts, unless the user set numba's CPU options
or SLSCAN_WIDE_VECTORS=0."""

import os
import subprocess
import sys

PROBE = """
import numpy as np
from numba import njit
import app.decode.fast.rows
from numba.core import codegen, registry

@njit
def scale(a, b):
    for i in range(a.shape[0]):
        b[i] = 2.0 * a[i]

a = np.ones(1000)
scale(a, a.copy())
asm = next(iter(scale.inspect_asm().values()))
host = codegen.get_host_cpu_features().split(",")
tm = registry.cpu_target.target_context.codegen()._tm_features
print("+avx512f" in host, tm.endswith(",-prefer-256-bit"), "zmm" in asm, tm)
"""


def _probe(**env: str) -> list[str]:
    clean = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_CPU", "SLSCAN_WIDE"))}
    run = subprocess.run([sys.executable, "-c", PROBE], env={**clean, **env}, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    return run.stdout.split()


def test_compiled_loops_use_512_bit_vectors_exactly_on_avx512_hosts():
    avx512, wide, zmm, _ = _probe()
    assert wide == avx512
    assert zmm == avx512  # the loop above was vectorised with zmm registers


def test_the_switch_keeps_llvm_s_choice():
    _, wide, zmm, _ = _probe(SLSCAN_WIDE_VECTORS="0")
    assert wide == "False" and zmm == "False"


def test_numba_cpu_features_set_by_the_user_win():
    _, wide, _, features = _probe(NUMBA_CPU_FEATURES="+sse2,+sse4.2")
    assert wide == "False" and features == "+sse2,+sse4.2"
