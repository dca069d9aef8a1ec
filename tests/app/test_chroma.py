"""Cameras whose colour is subsampled across the rows (YUYV 4:2:2, MJPEG 4:2:0): recognised from their format,
warned about with the stripe width their colour carries, or given it by `scheme.stripe_width: auto`; the
virtual camera emulates them (against its ground truth)."""

from __future__ import annotations

import warnings

import pytest
import yaml

from app.bench.accuracy import score
from app.chroma import stripe_width_for
from app.cli import main
from app.config import DEFAULT_CONFIG
from app.decode.pipeline import EmptyResultWarning, FrameSetDecoder
from app.session import build_session
from core.chroma import chroma_of_fourcc, subsample_chroma
from core.patterns import make_patterns
from drivers.sim.rig import VirtualRig

SMALL = {"camera_size": [320, 240], "projector_size": [512, 384]}


def test_formats_that_subsample_colour_are_recognised() -> None:
    assert chroma_of_fourcc("YUYV") == "4:2:2" and chroma_of_fourcc("MJPG") == "4:2:0"
    assert chroma_of_fourcc("GREY") is None and chroma_of_fourcc(None) is None


@pytest.mark.parametrize("chroma", ["4:2:2", "4:2:0"])
def test_a_subsampled_colour_camera_gets_its_warning_with_the_width_to_use(chroma, capsys) -> None:
    session = build_session(None, sim_overrides={**SMALL, "chroma": chroma})
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and chroma in err[0] and "scheme.stripe_width: 2" in err[0]
    assert session.notices == err and session.chroma == chroma
    assert build_session(None, sim_overrides=SMALL).notices == []  # full colour: nothing to say


def config_file(tmp_path, **scheme) -> str:
    data = yaml.safe_load(DEFAULT_CONFIG.read_text())
    data["sim"].update(SMALL, chroma="4:2:2")
    data["scheme"].update(scheme)
    path = tmp_path / "webcam.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


def test_stripe_width_auto_applies_the_width_and_silences_the_warning(tmp_path, capsys) -> None:
    session = build_session(config_file(tmp_path, stripe_width="auto"))
    assert session.patterns.params["stripe_width"] == 2 and session.notices == []
    assert capsys.readouterr().err == ""


def test_a_v4l2_webcam_is_recognised_from_its_fourcc(tmp_path, capsys) -> None:
    rig = VirtualRig.from_preset("face", ideal=True, **{k: tuple(v) for k, v in SMALL.items()})
    rig.calibration.save(tmp_path / "cal.yaml")
    data = yaml.safe_load(DEFAULT_CONFIG.read_text())
    data["rig"] = {
        "camera": {"driver": "v4l2", "device": 0, "fourcc": "MJPG"},
        "projector": {"driver": "pyglet", "screen": 1, "size": [512, 384]},
    }
    data["calibration"] = "cal.yaml"
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(data))
    session = build_session(path)  # (no device opens before make_loop)
    assert session.chroma == "4:2:0" and len(session.notices) == 1 and "camera v4l2" in session.notices[0]
    assert "stripe_width: 2" in capsys.readouterr().err


def test_unknown_chroma_is_a_one_line_error(tmp_path, capsys) -> None:
    data = yaml.safe_load(DEFAULT_CONFIG.read_text())
    data["sim"].update(camera_size=[64, 48], chroma="4:1:1")
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    assert main(["live", "--config", str(path), "--headless", "--frames", "2"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "sim.chroma" in err and "4:1:1" in err


@pytest.mark.parametrize("chroma", ["4:2:2", "4:2:0"])
def test_the_proposed_width_gives_back_the_coverage_subsampling_costs(chroma) -> None:
    # (640x480: at 320x240 the lens blur, scaled with the width, hides 4:2:2's loss on the face)
    rig = VirtualRig.from_preset("face")
    cal = rig.calibration
    cal.extra["camera_gamma"] = float(rig.options.camera_gamma)
    width = stripe_width_for(chroma, cal)
    assert width == 2
    cover = {}
    for w in (1, width):
        ps = make_patterns("two-shot", cal.projector_size, stripe_width=w)
        meta = {"scheme": "two-shot", "size": list(ps.size), "images": ps.names, **ps.params}
        frames = [rig.render(im) for im in ps.images]
        gt = rig.ground_truth
        dec = FrameSetDecoder("two-shot", meta, cal, rig.depth_range_mm)
        for name, fr in (("full", frames), ("sub", [subsample_chroma(f, chroma) for f in frames])):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", EmptyResultWarning)
                res = dec.decode(fr)
            cover[w, name] = score(res.stripes.column, res.depth, gt.column, gt.depth, gt.lit)[:2]
    assert cover[1, "sub"][0] < cover[1, "full"][0] - 0.04  # one-pixel stripes: the colour cannot carry them
    assert cover[width, "sub"][0] > cover[width, "full"][0] - 0.02 and cover[width, "sub"][1] > 0.99
