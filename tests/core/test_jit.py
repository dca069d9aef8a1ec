"""core.jit: numba's CPU target gets 512-bit vectors on AVX-512 hosts, unless the user set numba's CPU options
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
    _, wide, zmm, features = _probe(SLSCAN_WIDE_VECTORS="0")
    assert wide == "False" and not features.endswith(",-prefer-256-bit")
    # LLVM's own choice for this CPU model: the host's features handed to numba as the user's (Intel's AVX-512
    # servers prefer 256-bit vectors; AMD's Zen 4 and 5 do not)
    _, _, llvm_zmm, _ = _probe(NUMBA_CPU_FEATURES=features)
    assert zmm == llvm_zmm


def test_numba_cpu_features_set_by_the_user_win():
    _, wide, _, features = _probe(NUMBA_CPU_FEATURES="+sse2,+sse4.2")
    assert wide == "False" and features == "+sse2,+sse4.2"


CACHE_PROBE = """
import numpy as np
from numba.core import config
import core.jit
from app.triangulate import Triangulator  # noqa: F401  (a module of cached kernels)
from app.decode.pipeline import average_frames_of
a = np.zeros((4, 4, 3), np.uint8)
average_frames_of(a, a)
print(config.CACHE_DIR)
"""


def test_numba_caches_into_a_folder_keyed_by_the_sources(tmp_path):
    from core import jit

    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    run = subprocess.run(
        [sys.executable, "-c", CACHE_PROBE], env={**env, "NUMBA_CACHE_DIR": str(tmp_path)}, capture_output=True,
        text=True,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    folder = run.stdout.split()[-1]
    assert folder == str(tmp_path / f"slscan-{jit.source_digest()}")
    assert list((tmp_path / folder).rglob("*.nbi")), "the compiled kernels were not cached there"


def test_an_edit_of_any_file_that_uses_numba_moves_the_cache(tmp_path):
    from core import jit

    (tmp_path / "app" / "decode").mkdir(parents=True)
    helper = tmp_path / "app" / "decode" / "helper.py"
    helper.write_text("from numba import njit\n\n@njit(inline='always')\ndef one():\n    return 1\n")
    (tmp_path / "app" / "decode" / "kernel.py").write_text("import numba\nfrom app.decode.helper import one\n")
    plain = tmp_path / "app" / "plain.py"
    plain.write_text("X = 1\n")
    before = jit.source_digest(tmp_path)
    plain.write_text("X = 2\n")
    assert jit.source_digest(tmp_path) == before  # no compiled code: no effect on the cache
    helper.write_text(helper.read_text().replace("return 1", "return 2"))
    assert jit.source_digest(tmp_path) != before


def test_a_too_old_compiler_is_refused_in_one_line_naming_the_versions():
    from core import jit

    jit.check_compiler("0.62.0", "0.45.0", 20)
    for old in (("0.61.2", "0.44.0", 15), ("0.62.0", "0.44.0", 15), ("0.68.1", "0.50.0", 19)):
        try:
            jit.check_compiler(*old)
        except jit.CompilerVersionError as exc:
            msg = str(exc)
        else:
            raise AssertionError(f"{old} accepted")
        assert "\n" not in msg and f"numba {old[0]}" in msg and f"llvmlite {old[1]}" in msg
        assert "numba >= 0.62" in msg and "llvmlite >= 0.45" in msg
