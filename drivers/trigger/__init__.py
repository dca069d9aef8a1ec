"""Serial trigger box: protocol (PROTOCOL.md), pyserial driver, emulator, ATmega328P firmware."""

from drivers.trigger import serial_box  # noqa: F401  (registers "serial" in drivers.base.TRIGGERS)
