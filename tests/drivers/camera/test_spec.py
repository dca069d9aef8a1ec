"""Camera SPEC strings and config mappings -> drivers from the registry."""

from __future__ import annotations

import pytest

from core.errors import InputError
from drivers.camera.spec import CameraSpec, as_bool, load_camera_drivers, open_camera, parse_camera_spec


@pytest.mark.parametrize(
    ("text", "driver", "options"),
    [
        ("genicam:index=0", "genicam", {"index": "0"}),
        ("genicam:serial=0012345", "genicam", {"serial": "0012345"}),  # leading zeros kept: serials are text
        ("genicam:cti=/opt/x y/x.cti,model=acA1300", "genicam", {"cti": "/opt/x y/x.cti", "model": "acA1300"}),
        ("v4l2:/dev/video0", "v4l2", {"device": "/dev/video0"}),
        ("v4l2:0,fourcc=MJPG, width=1280", "v4l2", {"device": "0", "fourcc": "MJPG", "width": "1280"}),
        ("replay:/data/dump1,realtime=true", "replay", {"dump": "/data/dump1", "realtime": "true"}),
        ("sim", "sim", {}),
        ("SIM:", "sim", {}),
        ("genicam:pixel-format=Mono8", "genicam", {"pixel_format": "Mono8"}),
    ],
)
def test_parse(text, driver, options):
    spec = parse_camera_spec(text)
    assert spec == CameraSpec(driver, options)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (":index=0", "starts with no driver name"),
        ("v4l2:0,MJPG", "'MJPG' should be key=value"),
        ("sim:fast", "'fast' should be key=value"),
        ("genicam:index=0,index=1", "option 'index' given twice"),
        ("genicam:9x=1", "'9x' is not an option name"),
    ],
)
def test_parse_errors(text, message):
    with pytest.raises(InputError, match=message):
        parse_camera_spec(text)


def test_as_bool():
    assert as_bool("x", "Yes") is True and as_bool("x", "off") is False and as_bool("x", True) is True
    with pytest.raises(InputError, match="x='2' must be true or false"):
        as_bool("x", "2")


def test_registry_and_unknown_drivers_or_options():
    assert {"genicam", "v4l2", "replay"} <= set(load_camera_drivers())
    with pytest.raises(InputError, match=r"camera driver 'nikon' is unknown \(known: .*genicam.*replay.*v4l2"):
        open_camera("nikon:x=1")
    with pytest.raises(InputError, match="camera driver 'v4l2' has no option 'colour'"):
        open_camera("v4l2:0,colour=red")
    with pytest.raises(InputError, match="missing key 'driver'"):
        open_camera({"serial": "1"})
