"""core.jit_cache.merge_cache_folder: kernels compiled by separate processes into folders of their own, merged into
one, are all loaded from it by a third process, which compiles nothing."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

from core.jit_cache import merge_cache_folder

KERNEL = textwrap.dedent(
    """
    from numba import njit

    @njit(cache=True)
    def twice(x):
        return 2 * x
    """
)

CALL = textwrap.dedent(
    """
    import json, sys
    import numpy as np
    sys.path.insert(0, sys.argv[1])
    from kernel import twice
    values = {"float": 1.5, "int": 3, "complex": 1j}
    for kind in sys.argv[2].split(","):
        twice(values[kind])
    print(json.dumps({"hits": sum(twice.stats.cache_hits.values()), "misses": sum(twice.stats.cache_misses.values())}))
    """
)


def _call(tmp_path: Path, cache: Path, kinds: str) -> dict[str, int]:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    run = subprocess.run(
        [sys.executable, "-c", CALL, str(tmp_path / "src"), kinds], env=env, capture_output=True, text=True
    )
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout)


def test_signatures_compiled_apart_are_all_loaded_after_the_merge(tmp_path):
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "kernel.py").write_text(KERNEL)
    a, b, merged = tmp_path / "a", tmp_path / "b", tmp_path / "merged"
    assert _call(tmp_path, a, "float") == {"hits": 0, "misses": 1}
    assert _call(tmp_path, b, "int,complex") == {"hits": 0, "misses": 2}
    assert merge_cache_folder(a, merged) == 1
    assert merge_cache_folder(b, merged) == 2
    assert merge_cache_folder(b, merged) == 0  # (what it has already is kept)
    assert _call(tmp_path, merged, "float,int,complex") == {"hits": 3, "misses": 0}
    # the sources' own folders are untouched: each still has its own signatures only
    assert _call(tmp_path, a, "float") == {"hits": 1, "misses": 0}
    assert _call(tmp_path, b, "float") == {"hits": 0, "misses": 1}


def test_an_index_of_an_edited_source_is_replaced(tmp_path):
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "kernel.py").write_text(KERNEL)
    old, new = tmp_path / "old", tmp_path / "new"
    _call(tmp_path, old, "float,int")
    (tmp_path / "src" / "kernel.py").write_text(KERNEL + "\n# edited\n")  # another source stamp (size, mtime)
    _call(tmp_path, new, "complex")
    assert merge_cache_folder(new, old) == 1
    # the old source's kernels are gone from the index, not mixed with the new source's
    assert _call(tmp_path, old, "complex,float") == {"hits": 1, "misses": 1}
