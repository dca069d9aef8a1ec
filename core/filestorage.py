"""Reading OpenCV FileStorage files (YAML, XML, JSON, each optionally gzipped) in Python, never with OpenCV.

cv2.FileStorage aborts the whole process (heap corruption, failed asserts) on some malformed files, and a
calibration file comes from anywhere: so slscan parses what FileStorage writes with Python's own parsers, where a
bad file is an exception that becomes a one-line InputError. What FileStorage writes:

- YAML: a `%YAML:1.0` or `%YAML 1.2` line, then a mapping; matrices are tagged `!!opencv-matrix` (rows, cols, dt,
  data); PyYAML's safe loader with that one tag.
- XML: `<opencv_storage>` with one element per key; a matrix has `type_id="opencv-matrix"` and rows, cols, dt, data
  children (data: numbers separated by spaces), a sequence is its numbers separated by spaces, a mapping has child
  elements. Parsed with xml.etree; FileStorage never writes a DOCTYPE, so one (and with it every entity, the root of
  entity-expansion attacks) is refused before parsing.
- JSON: an object; a matrix is an object with "type_id": "opencv-matrix".
- gzip (`.gz`, any of the above): decompressed with the gzip module, at most MAX_BYTES.

The result maps each top-level key to a numpy array (a matrix), a number, a string, a list (a sequence) or a dict
(a mapping). The format is taken from the content, not the name.
"""

from __future__ import annotations

import gzip
import io
import json
import xml.etree.ElementTree as ET
import zlib
from pathlib import Path

import numpy as np
import yaml

from core.errors import InputError
from core.yamlfile import BoundedLoader

MAX_BYTES = 64 << 20  # a calibration is a few kB; response curves make it a few hundred
MAX_MATRIX = 4096  # rows and cols


class _BadMatrixError(ValueError):
    pass


def read_filestorage(path: Path) -> dict:
    """The top-level mapping of a FileStorage file, or InputError (one line, naming the file)."""
    raw = _read_bytes(path)
    try:
        text = raw.decode("utf-8")
        if "\x00" in text:
            raise UnicodeDecodeError("utf-8", raw, 0, 1, "NUL byte")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text (OpenCV FileStorage YAML, XML or JSON) file") from None
    head = text.lstrip()[:64]
    try:
        if head.startswith("<"):
            return _from_xml(text, path)
        if head.startswith(("{", "[")):
            return _from_json(text, path)
        return _from_yaml(text, path)
    except _BadMatrixError as exc:
        raise InputError(f"{path}: {exc}") from None


def _read_bytes(path: Path) -> bytes:
    try:
        with open(path, "rb") as f:
            raw = f.read(MAX_BYTES + 1)
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from None
    too_large = InputError(f"{path}: larger than {MAX_BYTES:,} bytes: not a calibration file")
    if len(raw) > MAX_BYTES:
        raise too_large
    if raw[:2] == b"\x1f\x8b":  # gzip's magic number, whatever the file's name
        try:
            with gzip.GzipFile(fileobj=io.BytesIO(raw)) as g:
                raw = g.read(MAX_BYTES + 1)
        except (OSError, EOFError, zlib.error) as exc:
            raise InputError(f"{path}: a damaged gzip file ({_first_line(exc)})") from None
    if len(raw) > MAX_BYTES:  # (decompressed: a gzip bomb stops here, MAX_BYTES read)
        raise too_large
    return raw


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _matrix(rows: object, cols: object, data: object) -> np.ndarray:
    if not (isinstance(rows, int) and isinstance(cols, int) and not isinstance(rows, bool)):
        raise _BadMatrixError("an opencv-matrix needs positive integer rows and cols")
    if not (0 < rows <= MAX_MATRIX and 0 < cols <= MAX_MATRIX):
        raise _BadMatrixError("an opencv-matrix needs positive integer rows and cols")
    if not isinstance(data, list) or len(data) != rows * cols:
        raise _BadMatrixError(f"an opencv-matrix of {rows}x{cols} needs {rows * cols} data values")
    values = [number(v) for v in data]
    if any(v is None for v in values):
        raise _BadMatrixError("an opencv-matrix has a value that is not a number")
    return np.array(values, np.float64).reshape(rows, cols)


def number(value: object) -> float | None:
    """A number as FileStorage writes one (an int, a float, or text such as "1e-05" or ".Nan"), else None."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int | float):
        return float(value)
    if isinstance(value, str):  # PyYAML leaves e.g. "1e-05" (no dot) as a string; XML text is always one
        text = value.strip()
        special = {".nan": float("nan"), ".inf": float("inf"), "-.inf": float("-inf")}
        if text.lower() in special:
            return special[text.lower()]
        try:
            return float(text)
        except ValueError:
            return None
    return None


# ---------------------------------------------------------------------------------------------- YAML


class _Loader(BoundedLoader):
    """PyYAML's safe loader (bounded in nesting: core/yamlfile.py) plus OpenCV's `!!opencv-matrix` tag."""


def _construct_matrix(loader: yaml.SafeLoader, node: yaml.Node) -> np.ndarray:
    if not isinstance(node, yaml.MappingNode):
        raise _BadMatrixError("an opencv-matrix must be a mapping")
    m = loader.construct_mapping(node, deep=True)
    return _matrix(m.get("rows"), m.get("cols"), m.get("data"))


_Loader.add_constructor("tag:yaml.org,2002:opencv-matrix", _construct_matrix)


def _from_yaml(text: str, path: Path) -> dict:
    lines = text.splitlines()
    if lines and lines[0].startswith("%YAML"):  # OpenCV writes "%YAML:1.0" or "%YAML 1.2"
        lines = lines[1:]
    try:
        loader = _Loader("\n".join(lines))
        try:
            doc = loader.get_single_data()
        finally:
            loader.dispose()
    except _BadMatrixError:
        raise
    except (yaml.YAMLError, ValueError, TypeError, RecursionError) as exc:
        raise InputError(f"{path}: not an OpenCV FileStorage YAML file ({_first_line(exc)})") from None
    if not isinstance(doc, dict):
        raise InputError(f"{path}: not an OpenCV FileStorage YAML file (expected a mapping at the top level)")
    return doc


# ---------------------------------------------------------------------------------------------- JSON


def _json_value(value: object, depth: int = 0) -> object:
    if depth > 64:
        raise _BadMatrixError("nested more than 64 levels deep")
    if isinstance(value, dict):
        if value.get("type_id") == "opencv-matrix":
            return _matrix(value.get("rows"), value.get("cols"), value.get("data"))
        return {k: _json_value(v, depth + 1) for k, v in value.items()}
    if isinstance(value, list):
        return [_json_value(v, depth + 1) for v in value]
    return value


def _from_json(text: str, path: Path) -> dict:
    # FileStorage writes comments in JSON as whole lines starting with //, and reads them back
    text = "\n".join("" if line.lstrip().startswith("//") else line for line in text.splitlines())
    text = text.replace("\\'", "'")  # and an apostrophe in a string as \', which JSON has no escape for
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not an OpenCV FileStorage JSON file ({exc.msg}, line {exc.lineno})") from None
    except RecursionError:
        raise InputError(f"{path}: not an OpenCV FileStorage JSON file (nested too deeply)") from None
    if not isinstance(doc, dict):
        raise InputError(f"{path}: not an OpenCV FileStorage JSON file (expected an object at the top level)")
    return {k: _json_value(v) for k, v in doc.items()}


# ---------------------------------------------------------------------------------------------- XML


def _xml_value(node: ET.Element, depth: int = 0) -> object:
    if depth > 64:
        raise _BadMatrixError("nested more than 64 levels deep")
    children = list(node)
    if node.get("type_id") == "opencv-matrix":
        parts = {c.tag: (c.text or "").strip() for c in children}
        rows, cols = _xml_int(parts.get("rows")), _xml_int(parts.get("cols"))
        return _matrix(rows, cols, parts.get("data", "").split())
    if children:
        if all(c.tag == "_" for c in children):  # a sequence of structures
            return [_xml_value(c, depth + 1) for c in children]
        return {c.tag: _xml_value(c, depth + 1) for c in children}
    text = (node.text or "").strip()
    if len(text) >= 2 and text[0] == text[-1] == '"':
        return text[1:-1]  # a quoted string
    tokens = text.split()
    if len(tokens) == 1:
        value = number(tokens[0])
        return tokens[0] if value is None else (int(value) if tokens[0].lstrip("+-").isdigit() else value)
    values = [number(t) for t in tokens]
    if tokens and all(v is not None for v in values):
        return values  # a sequence of numbers
    return text


def _xml_int(text: str | None) -> int | None:
    return int(text) if text is not None and text.lstrip("+").isdigit() else None


def _from_xml(text: str, path: Path) -> dict:
    if "<!DOCTYPE" in text or "<!ENTITY" in text:
        raise InputError(f"{path}: an XML file with a DOCTYPE or entities: not one OpenCV FileStorage writes")
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise InputError(f"{path}: not an OpenCV FileStorage XML file ({_first_line(exc)})") from None
    if root.tag != "opencv_storage":
        raise InputError(f"{path}: not an OpenCV FileStorage XML file (the root is <{root.tag}>, not <opencv_storage>)")
    return {child.tag: _xml_value(child) for child in root}
