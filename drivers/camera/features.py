"""GenICam features (SFNC names) on a device's node map: settings and hardware trigger.

Works on any object with the genapi NodeMap surface (`has_node(name)`, `getattr(nm, name)` with
`.value`, `.symbolics` for enumerations, `.min`/`.max` for numbers), so it is tested on a fake
node map as well as on viky.cti. Every error names the device and the feature.
"""

from __future__ import annotations

from typing import Any

from drivers.camera import pixels
from drivers.camera.errors import UnsupportedFeatureError


class NodeFeatures:
    def __init__(self, node_map: Any, device: str) -> None:
        self.nm = node_map
        self.device = device

    def has(self, feat: str) -> bool:
        return bool(self.nm.has_node(feat))

    def first(self, *names: str) -> str | None:
        return next((n for n in names if self.has(n)), None)

    def value(self, feat: str, default: Any = None) -> Any:
        return getattr(self.nm, feat).value if self.has(feat) else default

    def symbolics(self, feat: str) -> list[str]:
        try:
            return list(getattr(self.nm, feat).symbolics)
        except Exception:
            return []

    def writable(self, feat: str) -> bool:
        try:
            from genicam.genapi import is_writable

            return bool(is_writable(getattr(self.nm, feat).node))
        except Exception:
            return True  # unknown: let the write itself report a problem

    def set(self, feat: str, value: Any) -> None:
        if not self.has(feat):
            raise UnsupportedFeatureError(f"{self.device}: has no {feat} feature (asked to set it to {value!r})")
        node = getattr(self.nm, feat)
        try:
            node.value = value
        except Exception as exc:
            name = type(exc).__name__
            if name == "OutOfRangeException":
                lo, hi = getattr(node, "min", "?"), getattr(node, "max", "?")
                raise UnsupportedFeatureError(
                    f"{self.device}: {feat}={value} is outside its range {lo}..{hi}"
                ) from None
            if name.endswith("Exception"):  # genapi's AccessException, InvalidArgumentException, ...
                text = (str(exc).strip().splitlines() or [name])[0][:200]
                raise UnsupportedFeatureError(f"{self.device}: cannot set {feat}={value} ({text})") from None
            raise

    def set_enum(self, feat: str, value: str) -> None:
        if not self.has(feat):
            raise UnsupportedFeatureError(f"{self.device}: has no {feat} feature (cannot set {value!r})")
        options = self.symbolics(feat)
        if options and value not in options:
            raise UnsupportedFeatureError(
                f"{self.device}: {feat} {value!r} is not offered (the camera offers: {', '.join(options)})"
            )
        self.set(feat, value)

    def set_off(self, feat: str) -> None:
        """Switch an auto feature (ExposureAuto, GainAuto) off where there is one."""
        if self.has(feat) and self.writable(feat) and "Off" in self.symbolics(feat):
            self.set(feat, "Off")

    def supported_formats(self) -> str:
        offered = [f for f in self.symbolics("PixelFormat") if pixels.is_supported(f)]
        return ", ".join(offered) or "none offered by this camera"


def apply_settings(f: NodeFeatures, s: dict[str, Any]) -> str:
    """Pixel format, ROI, exposure, gain, frame rate (None = leave as is); returns the pixel format."""
    if s.get("pixel_format") is not None:
        if not pixels.is_supported(s["pixel_format"]):
            raise UnsupportedFeatureError(
                f"{f.device}: slscan cannot convert pixel format {s['pixel_format']!r} "
                f"(supported: {f.supported_formats()})"
            )
        f.set_enum("PixelFormat", s["pixel_format"])
    fmt = str(f.value("PixelFormat", "Mono8"))
    if not pixels.is_supported(fmt):
        raise UnsupportedFeatureError(
            f"{f.device}: pixel format {fmt!r} is not supported; set pixel_format to one of {f.supported_formats()}"
        )
    roi = (("width", "Width"), ("height", "Height"), ("offset_x", "OffsetX"), ("offset_y", "OffsetY"))
    if any(s.get(k) is not None for k, _ in roi):
        # Zero the offsets first so a larger width/height fits, then the size, then the offsets.
        for off in ("OffsetX", "OffsetY"):
            if f.has(off) and f.writable(off):
                f.set(off, 0)
        for key, feat in roi:
            if s.get(key) is not None and not (s[key] == 0 and not f.has(feat)):
                f.set(feat, s[key])
    if s.get("exposure_us") is not None:
        f.set_off("ExposureAuto")
        f.set(f.first("ExposureTime", "ExposureTimeAbs") or "ExposureTime", s["exposure_us"])
    if s.get("gain_db") is not None:
        f.set_off("GainAuto")
        f.set(f.first("Gain", "GainAbs") or "Gain", s["gain_db"])
    if s.get("frame_rate") is not None:
        if f.has("AcquisitionFrameRateEnable") and f.writable("AcquisitionFrameRateEnable"):
            f.set("AcquisitionFrameRateEnable", True)
        f.set(f.first("AcquisitionFrameRate", "AcquisitionFrameRateAbs") or "AcquisitionFrameRate", s["frame_rate"])
    return fmt


def configure_trigger(
    f: NodeFeatures, source: str | None, edge: str = "RisingEdge", selector: str = "FrameStart"
) -> None:
    """Hardware trigger on `source` (a line such as Line1), or free-running when source is None."""
    if source is None:
        if f.has("TriggerMode") and f.writable("TriggerMode"):
            if f.has("TriggerSelector") and selector in f.symbolics("TriggerSelector"):
                f.set("TriggerSelector", selector)
            f.set("TriggerMode", "Off")  # free-running, whatever the camera was left in
        return
    if not f.has("TriggerMode"):
        raise UnsupportedFeatureError(
            f"{f.device}: has no TriggerMode feature, so it cannot run hardware-triggered; "
            "remove `trigger` from the camera config or use a camera with a trigger input"
        )
    if f.has("TriggerSelector"):
        f.set_enum("TriggerSelector", selector)  # the other settings apply to the selected trigger
    f.set_enum("TriggerMode", "On")
    if not f.has("TriggerSource"):
        raise UnsupportedFeatureError(f"{f.device}: has no TriggerSource feature to select {source!r}")
    f.set_enum("TriggerSource", source)
    if f.has("TriggerActivation"):
        f.set_enum("TriggerActivation", edge)
    elif edge != "RisingEdge":
        raise UnsupportedFeatureError(f"{f.device}: has no TriggerActivation feature to select {edge}")
