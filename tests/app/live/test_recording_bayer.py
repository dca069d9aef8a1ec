"""A single-chip camera's raw Bayer frames end to end: recorded live as one-channel frames with the mosaic in
dump.yaml, replayed through the live pipeline and decoded offline, against the virtual rig's truth."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from app.cli import main
from app.commands.replay import replay_session
from app.config import DEFAULT_CONFIG
from app.live_pipeline import LivePipeline
from app.session import build_session, open_recorder
from core.dump import read_dump
from core.imageio import read_float_tiff

from .conftest import depth_agreement

# a stripe ~2 camera pixels wide, as at the bench's 640x480 under 1024x768
BAYER = {"camera_size": [320, 240], "projector_size": [512, 384], "bayer": "GRBG"}


def test_raw_bayer_dump_round_trips_through_record_replay_and_decode(tmp_path, capsys) -> None:
    session = build_session(None, sim_overrides=BAYER)
    assert session.mosaic == "GRBG"
    rec = open_recorder(session, tmp_path / "rec", png_level=1)
    pipe = LivePipeline(lambda: session.make_loop(timeout_s=3.0), None, max_frames=12, recorder=rec)
    pipe.start()
    pipe.wait()
    stats = rec.close()
    assert pipe.error is None and rec.message is None and stats.lost == 0 and stats.written >= 8
    truth = session.sim.rig.ground_truth

    dump = read_dump(tmp_path / "rec")
    assert dump.mosaic == "GRBG" and "mosaic: GRBG" in (tmp_path / "rec" / "dump.yaml").read_text()
    frame = dump.load_frame(0)
    assert frame.shape == (240, 320) and frame.dtype == np.uint8  # the mosaic itself, one channel

    replay = replay_session(str(tmp_path / "rec"))
    assert replay.mosaic == "GRBG"
    processor = replay.processor()
    results = []
    played = LivePipeline(lambda: replay.make_loop(), processor, on_result=results.append, max_frames=10**9)
    played.start()
    played.wait()
    assert played.error is None and played.stats.decoded >= 1 and played.stats.failed == 0
    assert played.latest.image.shape == (240, 320, 3)  # shown reconstructed
    correct, coverage = depth_agreement(played.latest.depth, truth)
    # (320x240, face: within 2 mm 94 %, 86 % of the lit pixels; the 3-CCD camera: 98 %, 94 %)
    assert correct > 0.9 and coverage > 0.75

    assert main(["decode", str(tmp_path / "rec"), "--out", str(tmp_path / "out")]) == 0
    depth = read_float_tiff(tmp_path / "out" / "depth_000000.tiff")
    correct, coverage = depth_agreement(depth, truth)
    assert correct > 0.9 and coverage > 0.75


@pytest.mark.parametrize(
    ("field", "value"),
    [("mosaic", "RGBG"), ("mosaic", 3)],
)
def test_unknown_mosaic_in_dump_yaml_is_a_one_line_error(tmp_path, capsys, field, value) -> None:
    assert main(["sim", "render", "--scene", "plane", "--scheme", "two-shot", "--camera-size", "64x48",
                 "--set", "bayer=RGGB", "--out", str(tmp_path / "d")]) == 0  # fmt: skip
    index = tmp_path / "d" / "dump.yaml"
    index.write_text(index.read_text().replace("mosaic: RGGB", f"{field}: {value}"))
    capsys.readouterr()
    assert main(["decode", str(tmp_path / "d"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "field 'mosaic'" in err


def test_unknown_bayer_in_config_is_a_one_line_error(tmp_path, capsys) -> None:
    data = yaml.safe_load(DEFAULT_CONFIG.read_text())
    data["sim"].update(camera_size=[64, 48], bayer="RGBX")
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(yaml.safe_dump(data))
    assert main(["live", "--config", str(cfg), "--headless", "--frames", "2"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "sim.bayer" in err and "RGBX" in err
