"""Serial ports on this machine, for `slscan devices` and for choosing the trigger box's port."""

from __future__ import annotations

from serial.tools import list_ports as _lp

# USB vendor ids of boards that run the trigger firmware (Arduino, Arduino clones' CH340, FTDI).
LIKELY_TRIGGER_VIDS = {0x2341: "Arduino", 0x2A03: "Arduino", 0x1A86: "CH340", 0x0403: "FTDI"}


def list_ports() -> list[dict]:
    """One dict per port: device, description, hwid, vid, pid, serial_number, manufacturer, product,
    likely_trigger (a USB serial chip that trigger boxes use). Sorted by device path."""
    out = []
    for p in _lp.comports():
        out.append(
            {
                "device": p.device,
                "description": p.description,
                "hwid": p.hwid,
                "vid": p.vid,
                "pid": p.pid,
                "serial_number": p.serial_number,
                "manufacturer": p.manufacturer,
                "product": p.product,
                "likely_trigger": p.vid in LIKELY_TRIGGER_VIDS,
            }
        )
    return sorted(out, key=lambda d: d["device"])
