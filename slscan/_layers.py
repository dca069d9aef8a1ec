"""The packages slscan is built of, loaded from beside this one whatever else is on sys.path.

slscan's layers are the top-level packages `core`, `drivers`, `app` and `calibration`, installed next to this
package. Python searches the script's folder (or the working directory) first, so a user's own `app.py` there
would be found instead of slscan's `app` and break every import of the library. Each layer is therefore loaded
here from the folder that holds this package, before anything imports it, and registered in sys.modules under its
name: every later `import app.x` (ours, or the user's) resolves to slscan's package.

Invariant: after this module runs, sys.modules[name].__path__ is ROOT / name for every name in LAYERS. A module of
that name imported before slscan from somewhere else cannot be replaced without breaking its importer: that is an
ImportError naming both files.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LAYERS = ("core", "drivers", "app", "calibration")  # in import order: each imports only the ones before it


def _load(name: str) -> None:
    folder = ROOT / name
    init = folder / "__init__.py"
    loaded = sys.modules.get(name)
    if loaded is not None:
        where = getattr(loaded, "__file__", None)
        if where is not None and Path(where).resolve() == init:
            return
        raise ImportError(
            f"slscan: the module {name!r} imported before slscan ({where or 'no file'}) hides slscan's own "
            f"package {folder}: rename that module, or import slscan before it"
        )
    spec = importlib.util.spec_from_file_location(name, init, submodule_search_locations=[str(folder)])
    if spec is None or spec.loader is None:  # (only if the installation lost the layer's files)
        raise ImportError(f"slscan: its package {folder} is missing: reinstall slscan")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise


for _name in LAYERS:
    _load(_name)
