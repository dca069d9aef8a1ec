"""numba's code generation, set once for the whole application before anything is compiled.

Import this module before numba compiles or loads anything (every module with compiled kernels does:
`import app.jit  # noqa: F401`).

LLVM gives Intel's AVX-512 server models (Skylake-X onwards) the tuning flag `prefer-256-bit`, so its loop
vectoriser stops at 256-bit vectors on them even though every instruction exists at 512 bits (a choice made
for the clock drop of the first AVX-512 parts). The decoder's loops are short and run over rows of runs and
pixels; at 512 bits they take ~10 % less time (two-shot decode + triangulate at 640x480: 4.12 -> 3.66 ms on
an Emerald Rapids core). Results are the same: LLVM keeps float reductions in order without fast-math, so
the vector width changes no rounding. numba reads the CPU features once, when its CPU target is created;
`NUMBA_CPU_NAME` or `NUMBA_CPU_FEATURES` set by the user win (numba's own settings), and
`SLSCAN_WIDE_VECTORS=0` keeps LLVM's choice (measured only on Emerald Rapids: CPUs that lower their clock
for 512-bit instructions or split them in two may not gain).
"""

from __future__ import annotations

import os

WIDE_VECTORS = "-prefer-256-bit"  # appended to the host's features where it has AVX-512


def use_wide_vectors() -> bool:
    """Let LLVM vectorise with 512-bit vectors on AVX-512 CPUs (see above); whether it was set."""
    if os.environ.get("SLSCAN_WIDE_VECTORS", "1") == "0":
        return False
    if os.environ.get("NUMBA_CPU_NAME") is not None or os.environ.get("NUMBA_CPU_FEATURES") is not None:
        return False
    from numba.core import codegen, config, registry

    if config.CPU_NAME is not None or config.CPU_FEATURES is not None:
        return config.CPU_FEATURES is not None and WIDE_VECTORS in config.CPU_FEATURES
    if "_toplevel_target_context" in registry.cpu_target.__dict__:
        return False  # numba's CPU target exists already: too late, it keeps LLVM's choice
    features = codegen.get_host_cpu_features()
    if "+avx512f" not in features.split(","):
        return False
    config.CPU_FEATURES = f"{features},{WIDE_VECTORS}"
    return True


use_wide_vectors()
