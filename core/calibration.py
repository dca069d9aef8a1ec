"""The camera–projector calibration and its OpenCV FileStorage YAML (docs/formats.md).

Geometry follows OpenCV: pinhole with (k1 k2 p1 p2 k3) distortion, millimetres, and
X_projector = R · X_camera + T (as cv2.stereoCalibrate with the camera first).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from core.errors import InputError
from core.filestorage import number as _number
from core.filestorage import read_filestorage

RMS_KEYS = ("camera_rms", "projector_rms", "stereo_rms")


@dataclass
class Calibration:
    camera_size: tuple[int, int]  # (w, h)
    camera_matrix: np.ndarray  # 3x3
    camera_distortion: np.ndarray  # (5,)
    projector_size: tuple[int, int]
    projector_matrix: np.ndarray
    projector_distortion: np.ndarray
    R: np.ndarray  # 3x3, camera -> projector
    T: np.ndarray  # (3,), mm
    rms: dict[str, float] = field(default_factory=dict)
    # Linear camera R, G, B (rows) produced by projector R, G, B (columns); None if not measured.
    color_mixing: np.ndarray | None = None
    extra: dict[str, np.ndarray | float] = field(default_factory=dict)  # e.g. response curves

    def __post_init__(self) -> None:
        self.camera_size = (int(self.camera_size[0]), int(self.camera_size[1]))
        self.projector_size = (int(self.projector_size[0]), int(self.projector_size[1]))
        self.camera_matrix = np.asarray(self.camera_matrix, np.float64).reshape(3, 3)
        self.projector_matrix = np.asarray(self.projector_matrix, np.float64).reshape(3, 3)
        self.camera_distortion = _dist5(self.camera_distortion)
        self.projector_distortion = _dist5(self.projector_distortion)
        self.R = np.asarray(self.R, np.float64).reshape(3, 3)
        self.T = np.asarray(self.T, np.float64).reshape(3)
        if self.color_mixing is not None:
            self.color_mixing = np.asarray(self.color_mixing, np.float64).reshape(3, 3)

    @property
    def baseline_mm(self) -> float:
        return float(np.linalg.norm(self.T))

    @property
    def projector_center_in_camera(self) -> np.ndarray:
        """Projector optical centre in camera coordinates: -R^T T."""
        return -self.R.T @ self.T

    def save(self, path: str | os.PathLike) -> None:
        path = Path(path)
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        if not fs.isOpened():
            raise InputError(f"{path}: cannot write calibration (check the folder exists and is writable)")
        try:
            _write_conventions(fs, path)
            fs.write("camera_size", np.array(self.camera_size, np.int32).reshape(1, 2))
            fs.write("camera_matrix", self.camera_matrix)
            fs.write("camera_distortion", self.camera_distortion.reshape(1, 5))
            fs.write("projector_size", np.array(self.projector_size, np.int32).reshape(1, 2))
            fs.write("projector_matrix", self.projector_matrix)
            fs.write("projector_distortion", self.projector_distortion.reshape(1, 5))
            fs.write("R", self.R)
            fs.write("T", self.T.reshape(3, 1))
            for key, value in self.rms.items():
                fs.write(key, float(value))
            if self.color_mixing is not None:
                fs.write("color_mixing", self.color_mixing)
            for key, value in self.extra.items():
                fs.write(key, np.asarray(value, np.float64) if not np.isscalar(value) else float(value))
        finally:
            fs.release()

    @classmethod
    def load(cls, path: str | os.PathLike) -> Calibration:
        path = Path(path)
        if not path.is_file():
            raise InputError(f"{path}: calibration file not found")
        doc = read_filestorage(path)

        def mat(key: str, shape: tuple[int, ...]) -> np.ndarray:
            if key not in doc:
                raise InputError(f"{path}: missing field '{key}'")
            m = _as_matrix(doc[key])
            if m is None:
                raise InputError(f"{path}: field '{key}' is not a matrix or a sequence of numbers")
            if m.size != int(np.prod(shape)):
                raise InputError(f"{path}: field '{key}' has {m.size} values, expected {int(np.prod(shape))}")
            if not np.all(np.isfinite(m)):
                raise InputError(f"{path}: field '{key}' has non-finite values")
            return m.reshape(shape)

        def size(key: str) -> tuple[int, int]:
            v = mat(key, (2,))
            if np.any(v < 1) or np.any(v > 1 << 16) or np.any(v != np.round(v)):
                raise InputError(f"{path}: field '{key}' must be two positive integers [w, h]")
            return int(v[0]), int(v[1])

        rms = {}
        for key in RMS_KEYS:
            if key in doc:
                value = _number(doc[key])
                if value is None:
                    raise InputError(f"{path}: field '{key}' must be a number")
                rms[key] = value
        mixing = mat("color_mixing", (3, 3)) if "color_mixing" in doc else None
        cal = cls(
            camera_size=size("camera_size"),
            camera_matrix=mat("camera_matrix", (3, 3)),
            camera_distortion=mat("camera_distortion", (5,)),
            projector_size=size("projector_size"),
            projector_matrix=mat("projector_matrix", (3, 3)),
            projector_distortion=mat("projector_distortion", (5,)),
            R=mat("R", (3, 3)),
            T=mat("T", (3,)),
            rms=rms,
            color_mixing=mixing,
            extra=_extra(doc),
        )
        cal.check(str(path))
        return cal

    def check(self, where: str = "calibration") -> None:
        """Refuse values no real rig has (the error names the field)."""
        for key, size in (("camera_matrix", self.camera_size), ("projector_matrix", self.projector_size)):
            K = getattr(self, key)
            if K[0, 0] <= 0 or K[1, 1] <= 0 or abs(K[2, 2] - 1) > 1e-9:
                raise InputError(f"{where}: field '{key}' is not a camera matrix (fx, fy > 0, K[2,2] = 1)")
            if max(abs(K[1, 0]), abs(K[2, 0]), abs(K[2, 1])) > 1e-9:
                raise InputError(f"{where}: field '{key}' is not upper-triangular (K[1,0], K[2,0], K[2,1] must be 0)")
            problem = _implausible_intrinsics(K, size)
            if problem:
                raise InputError(f"{where}: field '{key}' {problem}")
        for key in ("camera_distortion", "projector_distortion"):
            d = getattr(self, key)
            if np.max(np.abs(d[[0, 1, 4]])) > MAX_RADIAL or np.max(np.abs(d[[2, 3]])) > MAX_TANGENTIAL:
                raise InputError(
                    f"{where}: field '{key}' is implausible (|k1|, |k2|, |k3| <= {MAX_RADIAL:g}, "
                    f"|p1|, |p2| <= {MAX_TANGENTIAL:g}): {np.array2string(d, precision=4)}"
                )
        if abs(np.linalg.det(self.R) - 1) > 1e-3 or not np.allclose(self.R @ self.R.T, np.eye(3), atol=1e-3):
            raise InputError(f"{where}: field 'R' is not a rotation matrix")
        if self.baseline_mm <= 0:
            raise InputError(f"{where}: field 'T' is zero: camera and projector cannot share a centre")
        if self.color_mixing is not None and abs(np.linalg.det(self.color_mixing)) < 1e-9:
            raise InputError(f"{where}: field 'color_mixing' is singular and cannot be inverted")

    def check_camera_size(self, width: int, height: int, where: str) -> None:
        if (width, height) != self.camera_size:
            raise InputError(
                f"{where}: frames are {width}x{height} but the calibration's camera_size is "
                f"{self.camera_size[0]}x{self.camera_size[1]}"
            )


KNOWN_KEYS = {
    "camera_size", "camera_matrix", "camera_distortion", "projector_size", "projector_matrix",
    "projector_distortion", "R", "T", "color_mixing", *RMS_KEYS,
}  # fmt: skip


# Bounds no real lens reaches: focal lengths from a 175-degree fisheye (0.02 x the image width) to a 0.1-degree
# telescope (1000 x); pixels at most 5:1; the principal point within one image size of the image; distortion
# coefficients beyond these fold or tear the image inside its own frame.
FOCAL_RANGE = (0.02, 1000.0)
MAX_ASPECT = 5.0
MAX_RADIAL = 1000.0
MAX_TANGENTIAL = 1.0


def _implausible_intrinsics(K: np.ndarray, size: tuple[int, int]) -> str:
    """What makes K impossible for an image of `size` (w, h) pixels, or "" for a plausible one."""
    w, h = size
    fx, fy = K[0, 0], K[1, 1]
    lo, hi = FOCAL_RANGE[0] * max(w, h), FOCAL_RANGE[1] * max(w, h)
    if not (lo <= fx <= hi and lo <= fy <= hi):
        return f"has focal lengths fx={fx:g}, fy={fy:g} px outside {lo:g}..{hi:g} for a {w}x{h} image"
    if max(fx / fy, fy / fx) > MAX_ASPECT:
        return f"has fx={fx:g} and fy={fy:g}: pixels more than {MAX_ASPECT:g}:1 are not a real sensor"
    if abs(K[0, 1]) > fx:
        return f"has a skew K[0,1]={K[0, 1]:g} larger than fx"
    if not (-w <= K[0, 2] <= 2 * w and -h <= K[1, 2] <= 2 * h):
        return f"has its principal point ({K[0, 2]:g}, {K[1, 2]:g}) more than an image size outside the {w}x{h} image"
    return ""


def _extra(doc: dict) -> dict[str, np.ndarray | float]:
    """Every other top-level number or matrix (e.g. camera_gamma, response curves) into `extra`."""
    extra: dict[str, np.ndarray | float] = {}
    for key, value in doc.items():
        if key in KNOWN_KEYS:
            continue
        if isinstance(value, np.ndarray):
            if np.all(np.isfinite(value)):
                extra[key] = value
        elif (number := _number(value)) is not None:
            extra[key] = number
    return extra


def _as_matrix(value: object) -> np.ndarray | None:
    """A matrix, or a FileStorage sequence of numbers (`camera_size: [ 640, 480 ]`, what OpenCV writes for a
    cv::Size or a std::vector), flat or nested, as an array; None for anything else."""
    if isinstance(value, np.ndarray):
        return value
    if not isinstance(value, list) or not value:
        return None
    flat: list[object] = []
    stack = [value]
    while stack:  # (nested lists: rows of a matrix, as other tools write it in JSON)
        item = stack.pop()
        if isinstance(item, list):
            stack.extend(reversed(item))
        else:
            flat.append(item)
    numbers = [_number(v) for v in flat]
    if any(v is None for v in numbers):
        return None
    return np.array(numbers, np.float64)


CONVENTIONS = (  # (no apostrophes: OpenCV writes them into JSON as \\', which is not JSON)
    "slscan calibration in OpenCV conventions: pinhole with k1 k2 p1 p2 k3 distortion, pixels, millimetres",
    "R, T: the pose of the projector seen from the camera: X_projector = R * X_camera + T (as cv2.stereoCalibrate, "
    "camera first); T in mm",
    "camera_size, projector_size: [w, h] px; *_matrix: intrinsics in px; *_rms: reprojection errors in px",
)


def _write_conventions(fs: cv2.FileStorage, path: Path) -> None:
    """Say what R, T mean and the units: as comments (YAML, XML), as a string field in JSON (which has none)."""
    name = path.name.lower().removesuffix(".gz")
    if name.endswith(".json"):
        fs.write("conventions", " / ".join(CONVENTIONS))
        return
    for line in CONVENTIONS:
        fs.writeComment(line)


def _dist5(d: np.ndarray) -> np.ndarray:
    d = np.asarray(d, np.float64).ravel()
    if d.size > 5:
        raise ValueError("distortion has more than 5 coefficients (k1 k2 p1 p2 k3 expected)")
    return np.concatenate([d, np.zeros(5 - d.size)])
