"""`slscan devices`: the cameras, screens and serial ports this machine offers, with their SPECs."""

from __future__ import annotations

import argparse
import json

from core.errors import SlscanError

HELP = "list cameras (per GenTL producer and V4L2), screens and serial ports"

EPILOG = """\
examples:
  slscan devices                          # producers from GENICAM_GENTL64_PATH, V4L2, screens, ports
  slscan devices --cti viky               # also the virtual cameras of the producer the genicam wheel ships
  slscan devices --cti /opt/vendor/lib/x.cti --json

A camera's SPEC column is what `slscan grab --camera SPEC` and a config's `rig.camera` accept.
The virtual rig (`sim`) is always available.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "devices", help=HELP, description=HELP, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--cti", action="append", default=[], metavar="PATH", help="a GenTL producer (.cti), repeatable")
    p.add_argument("--display", default=None, help="X display to list screens of (default: $DISPLAY)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def _cameras(cti: list[str]) -> list[dict]:
    from drivers.camera.discovery import list_cameras

    return [{"driver": "sim", "spec": "sim", "name": "virtual rig camera"}, *list_cameras(cti)]


def _screens(display: str | None) -> list[dict]:
    from drivers.projector.screens import list_screens

    return list_screens(display)


def _ports() -> list[dict]:
    from drivers.trigger.ports import list_ports

    return list_ports()


def _collect(name: str, func, *args) -> dict:
    """One section; a device error (no display, no producer) is reported in the section, not raised."""
    try:
        return {"items": func(*args)}
    except SlscanError as exc:
        return {"items": [], "error": str(exc)}


def run(args: argparse.Namespace) -> int:
    result = {
        "cameras": _collect("cameras", _cameras, args.cti),
        "screens": _collect("screens", _screens, args.display),
        "serial_ports": _collect("serial ports", _ports),
    }
    if args.json:
        print(json.dumps(result, indent=1, default=str))
        return 0
    print("cameras:")
    for cam in result["cameras"]["items"]:
        if "error" in cam:
            print(f"  ({cam['driver']}) {cam['error']}")
            continue
        keys = ("name",) if cam.get("name") else ("vendor", "model")
        desc = " ".join(str(cam[k]) for k in (*keys, "access") if cam.get(k) not in (None, ""))
        print(f"  {cam.get('spec', '?'):40s} {desc}")
    _error_line(result["cameras"])
    print("screens:")
    for s in result["screens"]["items"]:
        print(f"  {s['index']}: {s['name']}  {s['width']}x{s['height']} at +{s['x']}+{s['y']}")
    _error_line(result["screens"])
    print("serial ports:")
    for p in result["serial_ports"]["items"]:
        hint = "  (looks like a trigger box board)" if p.get("likely_trigger") else ""
        print(f"  {p['device']}  {p.get('description') or ''}{hint}")
    if not result["serial_ports"]["items"] and "error" not in result["serial_ports"]:
        print("  (none)")
    _error_line(result["serial_ports"])
    return 0


def _error_line(section: dict) -> None:
    if "error" in section:
        print(f"  ({section['error']})")
