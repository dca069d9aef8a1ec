"""`slscan bench`: accuracy, speed and live figures, as tables or one JSON object."""

from __future__ import annotations

import argparse
import importlib
import json
import pkgutil
from types import ModuleType

from app import bench

HELP = "measure accuracy and speed on the virtual rig (tables, or --json)"


def sections() -> list[ModuleType]:
    mods = [importlib.import_module(f"{bench.__name__}.{m.name}") for m in pkgutil.iter_modules(bench.__path__)]
    return sorted((m for m in mods if hasattr(m, "FLAG")), key=lambda m: m.KEY)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help=HELP, description=HELP + ". With no section flag, every section runs.")
    for mod in sections():
        p.add_argument(mod.FLAG, dest=f"section_{mod.KEY}", action="store_true", help=mod.HELP)
        if hasattr(mod, "add_arguments"):
            mod.add_arguments(p)
    p.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    chosen = [m for m in sections() if getattr(args, f"section_{m.KEY}")] or [
        m for m in sections() if getattr(m, "DEFAULT", True)
    ]
    result: dict[str, list[dict]] = {}
    for mod in chosen:
        rows = mod.run(args)
        result[mod.KEY] = rows
        if not args.json:
            print(f"== {mod.KEY}")
            print(mod.format_table(rows))
            print()
    if args.json:
        print(json.dumps(result, indent=1))
    return 0
