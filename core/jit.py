"""numba's code generation, set once for the whole application before anything is compiled.

Import this module before numba compiles or loads anything (every module with compiled kernels does:
`import core.jit  # noqa: F401`).

LLVM gives Intel's AVX-512 server models (Skylake-X onwards) the tuning flag `prefer-256-bit`, so its loop
vectoriser stops at 256-bit vectors on them even though every instruction exists at 512 bits (a choice made
for the clock drop of the first AVX-512 parts). The decoder's loops are short and run over rows of runs and
pixels; at 512 bits they take ~10 % less time (two-shot decode + triangulate at 640x480: 4.12 -> 3.66 ms on
an Emerald Rapids core). Results are the same: LLVM keeps float reductions in order without fast-math, so
the vector width changes no rounding. numba reads the CPU features once, when its CPU target is created;
`NUMBA_CPU_NAME` or `NUMBA_CPU_FEATURES` set by the user win (numba's own settings), and
`SLSCAN_WIDE_VECTORS=0` keeps LLVM's choice (measured only on Emerald Rapids: CPUs that lower their clock
for 512-bit instructions or split them in two may not gain).

Two more guards, both before anything compiles:

- The compiler floor. The vector intrinsics (`app/decode/simd.py`) use `llvm.experimental.vector.compress`
  (LLVM 19+) and opaque-pointer intrinsic names: llvmlite 0.45 (LLVM 20, numba 0.62) is the first release with
  both. An older numba or llvmlite is refused at import with one line naming the versions found.
- One cache per source. numba's on-disk cache checks only the file that defines a function, but the decoder's
  kernels inline helpers from other files (simd.py, triangulate.py, ...): an edit there would leave a stale
  cached kernel. So numba's cache folder is keyed by a digest of every Python file of the application that
  mentions numba: `<base>/slscan-<digest>`, base = `NUMBA_CACHE_DIR` if set, else `~/.cache/slscan/numba`
  (`XDG_CACHE_HOME` respected). Any edit of such a file starts a fresh cache; folders unused for a week are
  removed.
"""

from __future__ import annotations

import os
import shutil
import time
from importlib import metadata
from pathlib import Path

from core.errors import SlscanError
from core.jit_cache import cache_base, source_digest

NUMBA_FLOOR = (0, 62)
LLVMLITE_FLOOR = (0, 45)
LLVM_FLOOR = 20
STALE_CACHE_S = 7 * 24 * 3600

WIDE_VECTORS = "-prefer-256-bit"  # appended to the host's features where it has AVX-512


def host_features() -> frozenset[str]:
    """The features of the CPU this runs on, as LLVM names them (without the '+')."""
    from numba.core import codegen

    return frozenset(f[1:] for f in codegen.get_host_cpu_features().split(",") if f.startswith("+"))


def target_features() -> frozenset[str]:
    """The features numba compiles for: its CPU_FEATURES setting where there is one (the user's, or
    use_wide_vectors'), else the host's; without the '+'."""
    from numba.core import config

    if config.CPU_FEATURES is None:
        return host_features()
    return frozenset(f[1:] for f in config.CPU_FEATURES.split(",") if f.startswith("+"))


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
    if "avx512f" not in host_features():
        return False
    config.CPU_FEATURES = f"{codegen.get_host_cpu_features()},{WIDE_VECTORS}"
    return True


class CompilerVersionError(SlscanError, ImportError):
    """numba or llvmlite older than the decoder's intrinsics need."""


def _release(version: str) -> tuple[int, ...]:
    parts = []
    for p in version.split(".")[:2]:
        digits = "".join(ch for ch in p if ch.isdigit())
        parts.append(int(digits or 0))
    return tuple(parts)


def check_compiler(numba_version: str, llvmlite_version: str, llvm_major: int) -> None:
    """Raise CompilerVersionError unless the versions meet NUMBA_FLOOR, LLVMLITE_FLOOR and LLVM_FLOOR."""
    if _release(numba_version) >= NUMBA_FLOOR and _release(llvmlite_version) >= LLVMLITE_FLOOR:
        if llvm_major >= LLVM_FLOOR:
            return
    need = f"numba >= {'.'.join(map(str, NUMBA_FLOOR))} with llvmlite >= {'.'.join(map(str, LLVMLITE_FLOOR))}"
    raise CompilerVersionError(
        f"slscan's decoder needs {need} (LLVM {LLVM_FLOOR}+); found numba {numba_version}, "
        f"llvmlite {llvmlite_version} (LLVM {llvm_major}): pip install -U numba llvmlite"
    )


def _installed_compiler() -> tuple[str, str, int]:
    import llvmlite.binding as llvm

    return metadata.version("numba"), metadata.version("llvmlite"), int(llvm.llvm_version_info[0])


def use_source_keyed_cache() -> Path:
    """Point numba's cache at cache_base()/slscan-<source_digest()> (see above); the folder in use."""
    from numba.core import config

    base = cache_base()
    folder = base / f"slscan-{source_digest()}"
    config.CACHE_DIR = str(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        os.utime(folder)  # in use: not stale for other checkouts' clean-up
    except OSError:
        pass  # (numba reports an unwritable cache itself, when it first writes)
    _remove_stale(base, folder)
    return folder


def _remove_stale(base: Path, keep: Path) -> None:
    try:
        old = [p for p in base.glob("slscan-*") if p != keep and time.time() - p.stat().st_mtime > STALE_CACHE_S]
    except OSError:
        return
    for p in old:
        shutil.rmtree(p, ignore_errors=True)


check_compiler(*_installed_compiler())
use_wide_vectors()
use_source_keyed_cache()
