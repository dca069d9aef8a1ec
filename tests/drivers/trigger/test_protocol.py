"""The line protocol itself: exact bytes, checksum, and resync after garbage."""

from __future__ import annotations

from functools import reduce

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.trigger import protocol as proto


def xor(body: bytes) -> int:
    return reduce(lambda a, b: a ^ b, body, 0)


def test_encode_exact_bytes():
    assert proto.encode("VER") == b"$VER*41\n"
    assert proto.encode("RATE", "60") == b"$RATE,60*28\n"
    assert proto.encode("T", 1, 0) == b"$T,1,0*55\n"
    body = b"OK,STAT,1,AUTO,INT,59.940,2,100,12345,7"
    assert proto.encode(*body.decode().split(",")) == b"$" + body + b"*%02X\n" % xor(body)


@pytest.mark.parametrize("bad", [("A$B",), ("A*B",), ("X" * 61,), ("\x01",)])
def test_encode_refuses_what_cannot_be_framed(bad):
    with pytest.raises(ValueError):
        proto.encode(*bad)


def test_decoder_resyncs_on_dollar_and_drops_garbage():
    d = proto.LineDecoder()
    data = b"\xff\x00noise$OK,VE$OK,VER,SLTRIG,1.0,3*4E\r\n$T,1\x07,0*55\n$T,2,1*57\n$T,3,0*00\n"
    out = list(d.feed(data))
    assert [type(o).__name__ for o in out] == ["Line", "Line", "BadLine"]
    assert out[0].fields == ("OK", "VER", "SLTRIG", "1.0", "3")
    assert out[1].fields == ("T", "2", "1")
    assert out[2].reason == "CHECKSUM"
    assert d.discarded == len(b"\xff\x00noise") + len(b"$OK,VE") + len(b"$T,1\x07") + len(b",0*55\n")


def test_decoder_long_lines_and_missing_checksum():
    strict, lax = proto.LineDecoder(), proto.LineDecoder(require_checksum=False)
    long = b"$" + b"A" * 70 + b"\n"
    assert [o.reason for o in strict.feed(long)] == ["LONG"]
    assert list(strict.feed(b"$VER\n")) == []  # the host never accepts unchecked lines
    (line,) = lax.feed(b"$ver\n")
    assert line.fields == ("ver",) and not line.had_checksum
    assert [o.reason for o in lax.feed(b"$" + b"B" * 61 + b"\n")] == ["LONG"]


@settings(max_examples=100, deadline=None)
@given(garbage=st.binary(max_size=80), split=st.integers(0, 200), count=st.integers(0, 2**32 - 1))
def test_any_garbage_then_a_line_decodes_that_line(garbage, split, count):
    line = proto.encode("T", count, count % 2)
    data = garbage + line
    d = proto.LineDecoder()
    out = list(d.feed(data[:split])) + list(d.feed(data[split:]))
    assert out and isinstance(out[-1], proto.Line) and out[-1].fields == ("T", str(count), str(count % 2))


@pytest.mark.parametrize(
    "text, mhz",
    [("60", 60000), ("59.94", 59940), ("1.001", 1001), ("250.000", 250000), ("0", 0), ("123456", 123456000)],
)
def test_parse_rate(text, mhz):
    assert proto.parse_rate(text) == mhz
    assert proto.parse_rate(proto.format_rate(mhz)) == mhz


@pytest.mark.parametrize("text", ["", "60.", ".5", "1.2345", "6O", "-1", "1e3", "1234567", "٣"])
def test_parse_rate_rejects(text):
    assert proto.parse_rate(text) is None
