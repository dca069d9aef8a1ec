"""`list_ports()` for `slscan devices`: what pyserial sees, as plain dicts."""

from __future__ import annotations

import os

from serial.tools import list_ports as pyserial_ports

from drivers.trigger.ports import LIKELY_TRIGGER_VIDS, list_ports

KEYS = {"device", "description", "hwid", "vid", "pid", "serial_number", "manufacturer", "product", "likely_trigger"}


def test_list_ports_matches_pyserial():
    ports = list_ports()
    assert [p["device"] for p in ports] == sorted(p.device for p in pyserial_ports.comports())
    for p in ports:
        assert set(p) == KEYS
        assert os.path.exists(p["device"])
        assert p["likely_trigger"] == (p["vid"] in LIKELY_TRIGGER_VIDS)
