"""Serial trigger box: protocol (PROTOCOL.md), pyserial driver, emulator, ATmega328P firmware."""
