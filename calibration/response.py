"""Colour response: what the camera sees when the projector shows flat levels of one primary.

From frames of flat projector levels (one primary at a time, plus black) on a white surface:
- each channel's projector->camera response curve: the camera's own channel mean (black removed)
  against the projector level, and a fitted power law  v = a * (level / 255) ** gamma;
- the 3x3 `color_mixing` matrix: column j is the linear camera R, G, B produced by projector
  primary j at full level (black removed), scaled to a unit diagonal;
- warnings when a channel is nearly saturated or too dark at full level.
Pure: frames in, numbers out. Camera values are taken as linear (machine-vision cameras run with
gamma off); `camera_gamma` linearises a camera that does not.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

CHANNELS = "RGB"
DEFAULT_LEVELS = (0, 32, 64, 96, 128, 160, 192, 224, 255)
SATURATED_FRACTION = 0.01  # of the surface pixels at the top code value
NEAR_SATURATION = 0.94  # of full scale: the mean this close to the top leaves no headroom
TOO_DARK = 0.06  # of full scale, linear: a primary whose full level gives less is too dark to decode


def level_image(size: tuple[int, int], channel: str, level: int) -> np.ndarray:
    """A flat projector image: `level` on one channel, 0 on the others (RGB uint8)."""
    w, h = size
    img = np.zeros((h, w, 3), np.uint8)
    img[..., CHANNELS.index(channel)] = level
    return img


def level_plan(levels: tuple[int, ...] = DEFAULT_LEVELS) -> list[tuple[str, int]]:
    """(channel, level) in projection order: black once, then each channel's non-zero levels."""
    plan = [("R", 0)]
    for ch in CHANNELS:
        plan += [(ch, lv) for lv in levels if lv > 0]
    return plan


@dataclass
class Response:
    levels: np.ndarray  # (L,) projector levels, 0 first
    curves: np.ndarray  # (3, L): camera channel c under projector primary c, black removed, camera units
    gamma: np.ndarray  # (3,) fitted exponent per channel
    color_mixing: np.ndarray  # (3, 3) columns = projector primaries, unit diagonal
    full_scale: float  # camera top code value (255 or 65535)
    warnings: list[str] = field(default_factory=list)

    def as_extra(self) -> dict[str, np.ndarray]:
        """For Calibration.extra: saved with the calibration."""
        return {
            "response_levels": self.levels.astype(np.float64).reshape(1, -1),
            "response_curves": self.curves.astype(np.float64),
            "response_gamma": self.gamma.astype(np.float64).reshape(1, 3),
        }


def surface_mask(white: np.ndarray, black: np.ndarray) -> np.ndarray:
    """Pixels of a bright, lit surface: white minus black above half its high percentile."""
    diff = white.astype(np.float64).mean(axis=2) - black.astype(np.float64).mean(axis=2)
    hi = np.percentile(diff, 98)
    return diff > 0.5 * hi if hi > 0 else np.zeros(diff.shape, bool)


def measure_response(
    frames: list[tuple[str, int, np.ndarray]],
    mask: np.ndarray | None = None,
    camera_gamma: float = 1.0,
) -> Response:
    """frames: (channel, level, camera RGB image); level 0 of any channel is the black frame."""
    if not frames:
        raise ValueError("no level frames")
    full = 65535.0 if frames[0][2].dtype == np.uint16 else 255.0
    blacks = [img for _, lv, img in frames if lv == 0]
    if not blacks:
        raise ValueError("no black (level 0) frame")

    def lin(img: np.ndarray) -> np.ndarray:
        return _linearise(img.astype(np.float64), camera_gamma, full)

    black_img = np.mean([lin(b) for b in blacks], axis=0)
    if mask is None:
        tops: dict[str, tuple[int, np.ndarray]] = {}
        for ch, lv, img in frames:
            if lv > tops.get(ch, (0, None))[0]:
                tops[ch] = (lv, img)
        white = np.sum([lin(img) for _, img in tops.values()], axis=0)
        mask = surface_mask(white, black_img)
    if mask.sum() < 50:
        raise ValueError("too few lit surface pixels to measure the colour response")
    black = black_img[mask].mean(axis=0)
    levels = sorted({lv for _, lv, _ in frames})
    curves = np.zeros((3, len(levels)))
    top_rgb = np.zeros((3, 3))
    warnings: list[str] = []
    for c, ch in enumerate(CHANNELS):
        best = -1
        sat = top_mean = 0.0
        for ch2, lv, img in frames:
            if ch2 != ch or lv == 0:
                continue
            v = lin(img)[mask].mean(axis=0) - black
            curves[c, levels.index(lv)] = v[c]
            if lv > best:
                best, top_rgb[:, c] = lv, v
                raw = img[mask][:, c]
                sat = float((raw >= full - 1).mean())
                top_mean = float(raw.astype(np.float64).mean())
        if best < 0:
            raise ValueError(f"no frames of projector channel {ch}")
        if sat > SATURATED_FRACTION or top_mean > NEAR_SATURATION * full:
            warnings.append(
                f"channel {ch} is nearly saturated at level {best} (mean {top_mean:.0f} of {full:.0f}, "
                f"{100 * sat:.1f} % clipped): lower the exposure or the projector brightness"
            )
        elif top_rgb[c, c] < TOO_DARK * full:
            warnings.append(
                f"channel {ch} is too dark at level {best} (linear signal {100 * top_rgb[c, c] / full:.1f} % of "
                f"full scale above black): raise the exposure or the projector brightness"
            )
    top = np.clip(top_rgb, 0, None)
    mixing = top / np.maximum(np.diag(top)[None, :], 1e-12)  # unit diagonal, as the virtual rig writes it
    gamma = np.array([_fit_gamma(np.array(levels, float), curves[c]) for c in range(3)])
    return Response(np.array(levels, float), curves, gamma, mixing, full, warnings)


def _linearise(v: np.ndarray, camera_gamma: float, full: float) -> np.ndarray:
    """Camera code values -> linear light in code units (the camera wrote v = full * lin ** (1/gamma))."""
    if camera_gamma == 1.0:
        return v
    return full * (np.clip(v, 0, None) / full) ** camera_gamma


def _fit_gamma(levels: np.ndarray, values: np.ndarray) -> float:
    """Least-squares exponent of v = a (L/255)^g through the origin, on the unclipped levels."""
    top = values.max()
    sel = (levels > 0) & (values > 0.02 * top) & (values < 0.97 * top)
    if sel.sum() < 2:
        sel = (levels > 0) & (values > 0)
    if sel.sum() < 2:
        return float("nan")
    x = np.log(levels[sel] / 255.0)
    y = np.log(values[sel])
    g, _ = np.polyfit(x, y, 1)
    return float(g)
