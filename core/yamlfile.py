"""Reading YAML files the same way everywhere: safe_load only, one-line errors naming the file."""

from __future__ import annotations

import os
from pathlib import Path

import yaml

from core.errors import InputError


def load_yaml(path: str | os.PathLike, error: type[InputError] = InputError) -> object:
    """The document in `path` (yaml.safe_load); bad YAML or bytes raise `error` naming the file."""
    path = Path(path)
    try:
        return yaml.safe_load(path.read_text())
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
