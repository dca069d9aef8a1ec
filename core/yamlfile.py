"""Reading YAML files the same way everywhere: safe_load only, bounded, one-line errors naming the file.

Every YAML slscan reads (configs, scene presets, dump indexes, pattern exports, calibration levels) is
untrusted input: a document nested thousands of levels deep makes PyYAML's recursive composer raise
RecursionError, and a huge file is read whole. So documents are parsed by `parse_yaml`: at most
MAX_BYTES, nested at most MAX_DEPTH levels (slscan's own files use fewer than ten), else a YAMLError
that the callers turn into one line naming the file.
"""

from __future__ import annotations

import os
from pathlib import Path

import yaml

from core.errors import InputError

MAX_DEPTH = 64  # nesting levels of a document
MAX_BYTES = 256 * 1024 * 1024  # a dump index of a million frames is ~100 MB


class BoundedLoader(yaml.SafeLoader):
    """yaml.SafeLoader that refuses documents nested deeper than MAX_DEPTH (before the recursion limit)."""

    def compose_node(self, parent: yaml.Node | None, index: object) -> yaml.Node:  # type: ignore[override]
        depth = getattr(self, "_depth", 0) + 1
        if depth > MAX_DEPTH:
            raise yaml.composer.ComposerError(
                None, None, f"nested deeper than {MAX_DEPTH} levels", self.peek_event().start_mark
            )
        self._depth = depth
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth = depth - 1


def parse_yaml(text: str) -> object:
    """yaml.safe_load of text, bounded in size and nesting (a yaml.YAMLError beyond either)."""
    if len(text) > MAX_BYTES:
        raise yaml.YAMLError(f"larger than {MAX_BYTES // (1024 * 1024)} MB")
    loader = BoundedLoader(text)
    try:
        return loader.get_single_data()
    finally:
        loader.dispose()


def load_yaml(path: str | os.PathLike, error: type[InputError] = InputError) -> object:
    """The document in `path` (yaml.safe_load); bad YAML or bytes raise `error` naming the file."""
    path = Path(path)
    try:
        if path.stat().st_size > MAX_BYTES:
            raise error(f"{path}: larger than {MAX_BYTES // (1024 * 1024)} MB, not read")
        return parse_yaml(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise error(f"{path}: not valid YAML ({first})") from None
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror})") from None


def load_yaml_mapping(path: str | os.PathLike, error: type[InputError] = InputError) -> dict:
    """Like load_yaml, for files whose top level must be a mapping."""
    data = load_yaml(path, error)
    if not isinstance(data, dict):
        raise error(f"{path}: expected a mapping at the top level")
    return data
