"""GenICam feature setting on a node map that has what viky lacks (trigger, exposure, gain, offsets).

The fake mimics genapi: enumerations reject values outside `symbolics`, numbers outside
[min, max] raise an exception named OutOfRangeException; every write is logged in order.
"""

from __future__ import annotations

import pytest

from drivers.camera.errors import UnsupportedFeatureError
from drivers.camera.features import NodeFeatures, apply_settings, configure_trigger


class OutOfRangeException(Exception):  # noqa: N818 (genapi's name, matched by the driver)
    pass


class AccessException(Exception):  # noqa: N818
    pass


class Node:
    def __init__(self, nm, name, value, symbolics=None, lo=None, hi=None, locked=False):
        self._nm, self._name, self._value = nm, name, value
        self.symbolics, self.min, self.max, self.locked = symbolics, lo, hi, locked

    @property
    def value(self):
        return self._value

    @value.setter
    def value(self, v):
        if self.locked:
            raise AccessException(f"Node '{self._name}' is not writable")
        if self.symbolics is not None and v not in self.symbolics:
            raise ValueError("never reached: the driver checks symbolics first")
        if self.min is not None and not self.min <= v <= self.max:
            raise OutOfRangeException(f"{v} out of range")
        self._nm.log.append((self._name, v))
        self._value = v


class NodeMap:
    def __init__(self, **nodes):
        self.log: list = []
        self._nodes = {k: Node(self, k, *v) for k, v in nodes.items()}

    def has_node(self, name):
        return name in self._nodes

    def __getattr__(self, name):
        try:
            return self.__dict__["_nodes"][name]
        except KeyError:
            raise AttributeError(name) from None


def machine_vision_camera(**overrides) -> NodeMap:
    nodes = {
        "PixelFormat": ("Mono8", ["Mono8", "Mono12p", "BayerRG8", "YCbCr422_8"]),
        "Width": (1280, None, 16, 1280),
        "Height": (1024, None, 16, 1024),
        "OffsetX": (0, None, 0, 1264),
        "OffsetY": (0, None, 0, 1008),
        "ExposureAuto": ("Continuous", ["Off", "Once", "Continuous"]),
        "ExposureTime": (10000.0, None, 20.0, 1e6),
        "GainAuto": ("Continuous", ["Off", "Continuous"]),
        "Gain": (0.0, None, 0.0, 24.0),
        "AcquisitionFrameRateEnable": (False, None),
        "AcquisitionFrameRate": (30.0, None, 1.0, 200.0),
        "TriggerSelector": ("FrameStart", ["AcquisitionStart", "FrameStart"]),
        "TriggerMode": ("Off", ["Off", "On"]),
        "TriggerSource": ("Software", ["Software", "Line1", "Line3"]),
        "TriggerActivation": ("RisingEdge", ["RisingEdge", "FallingEdge", "AnyEdge"]),
    }
    nodes.update(overrides)
    return NodeMap(**{k: v for k, v in nodes.items() if v is not None})


def test_hardware_trigger_is_set_in_sfnc_order():
    nm = machine_vision_camera()
    configure_trigger(NodeFeatures(nm, "cam A"), "Line1", "FallingEdge")
    assert nm.log == [
        ("TriggerSelector", "FrameStart"),  # select first: the others apply to the selected trigger
        ("TriggerMode", "On"),
        ("TriggerSource", "Line1"),
        ("TriggerActivation", "FallingEdge"),
    ]


def test_no_trigger_means_free_running_whatever_the_camera_was_left_in():
    nm = machine_vision_camera(TriggerMode=("On", ["Off", "On"]))
    configure_trigger(NodeFeatures(nm, "cam A"), None)
    assert nm.TriggerMode.value == "Off"


@pytest.mark.parametrize(
    ("overrides", "source", "message"),
    [
        ({}, "Line2", r"cam A: TriggerSource 'Line2' is not offered \(the camera offers: Software, Line1, Line3\)"),
        ({"TriggerMode": None}, "Line1", "cam A: has no TriggerMode feature, so it cannot run hardware-triggered"),
        ({"TriggerSource": None}, "Line1", "cam A: has no TriggerSource feature to select 'Line1'"),
        ({"TriggerSelector": ("AcquisitionStart", ["AcquisitionStart"])}, "Line1", "TriggerSelector 'FrameStart' is n"),
    ],
)
def test_trigger_errors_name_device_and_feature(overrides, source, message):
    with pytest.raises(UnsupportedFeatureError, match=message):
        configure_trigger(NodeFeatures(machine_vision_camera(**overrides), "cam A"), source)


def test_settings_applied_with_auto_modes_off_and_offsets_last():
    nm = machine_vision_camera(OffsetX=(600, None, 0, 1264))
    settings = {
        "pixel_format": "BayerRG8",
        "width": 800,
        "height": 600,
        "offset_x": 240,
        "offset_y": 200,
        "exposure_us": 4000.0,
        "gain_db": 6.0,
        "frame_rate": 60.0,
    }
    assert apply_settings(NodeFeatures(nm, "cam A"), settings) == "BayerRG8"
    assert nm.log == [
        ("PixelFormat", "BayerRG8"),
        ("OffsetX", 0),  # offsets zeroed first, so the new width fits whatever the old offset was
        ("OffsetY", 0),
        ("Width", 800),
        ("Height", 600),
        ("OffsetX", 240),
        ("OffsetY", 200),
        ("ExposureAuto", "Off"),  # auto modes off before the manual value
        ("ExposureTime", 4000.0),
        ("GainAuto", "Off"),
        ("Gain", 6.0),
        ("AcquisitionFrameRateEnable", True),
        ("AcquisitionFrameRate", 60.0),
    ]


def test_older_cameras_abs_feature_names():
    nm = machine_vision_camera(
        ExposureTime=None,
        ExposureTimeAbs=(100.0, None, 10.0, 1e5),
        AcquisitionFrameRate=None,
        AcquisitionFrameRateAbs=(10.0, None, 1.0, 100.0),
    )
    apply_settings(NodeFeatures(nm, "cam B"), {"exposure_us": 500.0, "frame_rate": 25.0})
    assert nm.ExposureTimeAbs.value == 500.0 and nm.AcquisitionFrameRateAbs.value == 25.0


@pytest.mark.parametrize(
    ("settings", "overrides", "message"),
    [
        ({"gain_db": 30.0}, {}, r"cam A: Gain=30.0 is outside its range 0.0..24.0"),
        ({"pixel_format": "YCbCr422_8"}, {}, r"convert pixel format 'YCbCr422_8' \(supported: Mono8, Mono12p, B"),
        ({}, {"PixelFormat": ("YCbCr422_8", ["YCbCr422_8", "Mono8"])}, "pixel format 'YCbCr422_8' is not supported"),
        ({"exposure_us": 100.0}, {"ExposureTime": (1.0, None, 1.0, 10.0, True)}, "cannot set ExposureTime=100.0 .*no"),
    ],
)
def test_setting_errors(settings, overrides, message):
    with pytest.raises(UnsupportedFeatureError, match=message):
        apply_settings(NodeFeatures(machine_vision_camera(**overrides), "cam A"), settings)
