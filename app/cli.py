"""The `slscan` command line: subcommands are discovered from `app/commands/`."""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
import warnings
from collections.abc import Sequence
from typing import NoReturn

from app import commands
from app.termination import exit_status, stop_cleanly_on_sigterm, stopped_by
from core.errors import SlscanError

DESCRIPTION = """\
slscan: a live structured-light 3D scanner (colour-stripe patterns after Je, Lee & Park, 2004).

A projector throws colour-stripe patterns, a synchronised camera films them, and every frame set
becomes a depth map and a point cloud. With no hardware configured, slscan runs on a virtual rig
(config/sim.yaml): a simulated projector, camera and trigger over a rendered scene.
"""

EPILOG = "Run `slscan COMMAND --help` for the options of one command."


class OneLineErrorParser(argparse.ArgumentParser):
    """Usage mistakes print one line (with a pointer to --help) and exit with status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineErrorParser(
        prog="slscan",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineErrorParser)
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{commands.__name__}.{info.name}")
        register = getattr(module, "register", None)
        if register is not None:
            register(sub)
    return parser


def _one_line_warning(message: Warning | str, category: type[Warning], *_: object, **__: object) -> None:
    """Our warnings (UserWarning subclasses, e.g. a depth range that decodes nothing) as one line on stderr."""
    print(f"slscan: warning: {message}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    with warnings.catch_warnings():  # (restored on return: an in-process caller keeps its own warning handling)
        warnings.showwarning = _one_line_warning
        return _main(argv)


def _main(argv: Sequence[str] | None) -> int:
    try:
        parser = build_parser()  # (imports every command: a missing or too old library is said here)
    except SlscanError as exc:
        print(f"slscan: error: {exc}", file=sys.stderr)
        return 2
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) or a usage error (2, already printed as one line)
        return exc.code if isinstance(exc.code, int) else 2
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help()
        return 2
    stop_cleanly_on_sigterm()
    try:
        return int(func(args) or 0)
    except SlscanError as exc:
        print(f"slscan {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except MemoryError:  # (inputs are bounded where they are read: this is the net under those bounds)
        print(
            f"slscan {args.command}: error: out of memory: the input asks for more than this machine holds",
            file=sys.stderr,
        )
        return 2
    except OSError as exc:  # a file system refusal no check foresaw (a name too long, a read-only disk, ...)
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"slscan {args.command}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        print(f"slscan {args.command}: {stopped_by(exc)}", file=sys.stderr)
        return exit_status(exc)


if __name__ == "__main__":
    sys.exit(main())
