"""`slscan grab`: frames saved from real cameras (viky.cti, a dump replay), and one-line errors."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from app.cli import main
from core.imageio import read_rgb
from drivers.camera.gentl import HUB


def test_grab_from_viky_in_a_subprocess(run_cli, tmp_path):
    out = tmp_path / "shots"
    r = run_cli(
        "grab",
        "--camera",
        "genicam:cti=viky,serial=2,pixel_format=RGBa8,policy=oldest",
        "--frames",
        "3",
        "--out",
        out,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    assert "grabbed 3 frame(s) from GenICam camera Viky serial=2 (VikyTL_DEV_blue)" in r.stdout
    index = yaml.safe_load((out / "frames.yaml").read_text())
    assert index["format"] == "slscan-grab" and index["device"].endswith("(VikyTL_DEV_blue)")
    assert [f["frame_id"] for f in index["frames"]] == [1, 2, 3]
    ts = [f["timestamp_ns"] for f in index["frames"]]
    assert ts == sorted(ts) and len(set(ts)) == 3
    assert index["stats"]["frames"] == 3 and index["stats"]["lost"] == 0
    img = read_rgb(out / index["frames"][0]["file"])
    assert img.shape == (400, 400, 3)
    assert {tuple(v) for v in np.unique(img.reshape(-1, 3), axis=0)} == {(255, 255, 255), (0, 0, 255)}


def test_grab_from_a_replay_keeps_pixels_and_tags(make_dump, truth, tmp_path, capsys):
    dump = make_dump()
    out = tmp_path / "g"
    assert main(["grab", "--camera", f"replay:{dump}", "--frames", "4", "--out", str(out)]) == 0
    index = yaml.safe_load((out / "frames.yaml").read_text())
    assert [f["frame_id"] for f in index["frames"]] == truth.ids[:4]
    assert [f["pattern"] for f in index["frames"]] == [0, 1, 0, 1]
    for i, f in enumerate(index["frames"]):
        np.testing.assert_array_equal(read_rgb(out / f["file"]), truth.image(i))
    # asking for more than the dump holds: the frames there are saved, and a warning says so
    assert main(["grab", "--camera", f"replay:{dump}", "--frames", "9", "--out", str(tmp_path / "all")]) == 0
    assert "the dump ended after 6 of 9 frames" in capsys.readouterr().err
    assert len(yaml.safe_load((tmp_path / "all" / "frames.yaml").read_text())["frames"]) == 6


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("genicam:cti=viky,serial=9", "no GenICam camera matches serial=9; found: GenICam camera Viky serial=0"),
        ("genicam:cti=viky,serial=0,trigger=Line1", "Viky serial=0 (VikyTL_DEV_red): has no TriggerMode feature"),
        ("genicam:cti=viky,serial=0,pixel_format=BayerGB8", "PixelFormat 'BayerGB8' is not offered"),
        ("genicam:cti=/no/such.cti", "/no/such.cti: GenTL producer (.cti) not found"),
        ("genicam:use_env=false", "no GenTL producer (.cti) found: set `cti:`"),
        ("v4l2:/dev/video7", "/dev/video7: no such V4L2 device"),
        ("nikon", "camera driver 'nikon' is unknown"),
    ],
)
def test_errors_are_one_line_exit_2_and_write_nothing(spec, message, tmp_path, capsys):
    out = tmp_path / "g"
    assert main(["grab", "--camera", spec, "--frames", "2", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("slscan grab: error: ") and message in err
    assert not out.exists() and not list(tmp_path.iterdir())
    assert HUB.open_count == 0


def test_busy_camera(tmp_path, capsys):
    from drivers.camera.genicam import GenICamCamera

    with GenICamCamera(cti="viky", serial="1", use_env=False):
        assert main(["grab", "--camera", "genicam:cti=viky,serial=1", "--out", str(tmp_path / "g")]) == 2
    assert "Viky serial=1 (VikyTL_DEV_green) is in use" in capsys.readouterr().err


def test_timeout_and_bad_arguments(tmp_path, capsys):
    spec = "genicam:cti=viky,serial=0,frame_rate=1,policy=oldest"
    assert main(["grab", "--camera", spec, "--frames", "2", "--timeout", "0.2", "--out", str(tmp_path / "t")]) == 2
    assert "no frame within the timeout" in capsys.readouterr().err
    assert main(["grab", "--camera", "sim", "--frames", "0", "--out", str(tmp_path / "z")]) == 2
    assert "argument --frames: '0' must be greater than 0" in capsys.readouterr().err


@pytest.mark.slow  # the virtual rig's set-up takes seconds (another area's cost, not the grab's)
def test_grab_from_the_virtual_rig(tmp_path):
    pytest.importorskip("drivers.sim.devices")
    out = tmp_path / "sim"
    assert main(["grab", "--camera", "sim", "--frames", "2", "--out", str(out)]) == 0
    index = yaml.safe_load((out / "frames.yaml").read_text())
    assert [f["frame_id"] for f in index["frames"]] == [1, 2]
    img = read_rgb(out / "000001.png")
    assert img.ndim == 3 and img.shape[2] == 3 and img.std() > 0  # a rendered scene, not a blank
