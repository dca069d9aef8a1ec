"""app.jit: numba's CPU target gets 512-bit vectors on AVX-512 hosts, unless the user set numba's CPU options."""

import os
import subprocess
import sys

PROBE = """
import app.decode.kernels
from numba.core import codegen, registry
host = codegen.get_host_cpu_features().split(",")
tm = registry.cpu_target.target_context.codegen()._tm_features
print("+avx512f" in host, tm.endswith(",-prefer-256-bit"), tm)
"""


def _probe(**env: str) -> list[str]:
    clean = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CPU")}
    run = subprocess.run([sys.executable, "-c", PROBE], env={**clean, **env}, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    return run.stdout.split()


def test_the_target_prefers_512_bit_vectors_exactly_on_avx512_hosts():
    avx512, wide, _ = _probe()
    assert wide == avx512


def test_numba_cpu_features_set_by_the_user_win():
    _, wide, features = _probe(NUMBA_CPU_FEATURES="+sse2")
    assert wide == "False" and features == "+sse2"
