"""White-light texture frames in the live loop on the virtual rig: every N frames, never in a set, recorded with
their tag, colouring the clouds after them with the object's own colour; the headless run's saved scan and its
scan.yaml."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from app.cli import main
from app.framesets import group_frame_sets
from app.live_pipeline import LivePipeline
from app.session import build_session, open_recorder
from core.dump import read_dump
from core.errors import InputError
from core.imageio import read_float_tiff, read_rgb
from core.scan_sidecar import read_scan_info
from core.wallclock import now_ns, parse_wall_clock

from .conftest import SMALL, depth_agreement

EVERY = 10
FACE_ALBEDO = np.array([0.78, 0.56, 0.46])  # config/scenes/face.yaml: the relief's colour


def _face_chroma(session, depth: np.ndarray, image: np.ndarray) -> np.ndarray:
    """The median colour of the face's pixels with depth (nearer than the wall behind), made linear (the rig's camera
    gamma) and unmixed (its calibration's colour mixing), as r, g, b summing to 1."""
    rig = session.sim.rig
    gt = rig.ground_truth.depth
    face = (depth > 0) & (gt > 0) & (gt < gt.max() - 20.0)
    linear = (np.median(image[face].astype(np.float64), axis=0) / 255.0) ** rig.options.camera_gamma
    albedo = np.linalg.solve(np.asarray(rig.calibration.color_mixing, np.float64), linear)
    return albedo / albedo.sum()


def test_texture_every_n_frames_is_never_paired_and_colours_the_clouds(tmp_path, sim_session):
    session = build_session(None, sim_overrides=SMALL)
    session.texture_every = EVERY
    processor = sim_session[1]  # the same rig geometry and patterns: the same decoder
    results = []
    rec = open_recorder(session, tmp_path / "rec")
    pipe = LivePipeline(
        lambda: session.make_loop(timeout_s=3.0), processor, max_frames=90, recorder=rec, on_result=results.append
    )
    pipe.start()
    pipe.wait()
    rec.close()
    cap = pipe.capture
    assert pipe.error is None and rec.stats.lost == 0
    # (a loaded machine may leave a tick without its flip: untracked, never paired)
    assert cap.frames == 90 and cap.mistagged == cap.duplicates == cap.out_of_order == 0
    cam = session.sim.camera
    dump = read_dump(tmp_path / "rec")
    textures = [dump.frames[i].frame_id for i in dump.texture_indices()]
    # the texture frames took their own ticks, every EVERY-th (the camera kept its rate: no frame lost for them)
    assert len(textures) == cap.textures >= 90 // EVERY - 2
    assert all(cam.truth(i) == 2 for i in textures) and all(d % EVERY == 0 for d in np.diff(textures))
    assert dump.texture_pattern == 2 and all(cam.truth(f.frame_id) == f.pattern for f in dump.frames)
    # no set takes a texture frame; each set's frames saw their patterns; the clouds after a texture frame use it
    assert len(results) >= 90 - 2 * len(textures) - 12 - 4 * cap.refused
    for res in results:
        ids = res.frameset.frame_ids
        assert [cam.truth(i) for i in ids] == [0, 1] and max(ids) - min(ids) == 1, ids
        before = [t for t in textures if t < min(ids)]
        assert (res.texture.frame_id if res.texture is not None else None) == (before[-1] if before else None)
    late = [r for r in results if r.texture is not None]
    assert len(late) >= len(results) // 2
    res = late[-1]
    correct, _ = depth_agreement(res.depth, session.sim.rig.ground_truth)
    assert correct > 0.95
    albedo = FACE_ALBEDO / FACE_ALBEDO.sum()
    assert np.abs(_face_chroma(session, res.depth, res.colour_image) - albedo).max() < 0.05
    assert np.abs(_face_chroma(session, res.depth, res.image) - albedo).max() > 0.1  # a stripe frame's colour
    # the recording: pairs as live, with the texture frames in no set, and decodes coloured by them
    tags = [(f.frame_id, f.pattern) for f in dump.frames]
    sets, stats = group_frame_sets(tags, "two-shot", 2, texture_pattern=2)
    assert stats.textures == len(textures) and stats.bad_tags == 0
    assert not {dump.frames[i].frame_id for s in sets for i in s.indices} & set(textures)
    # replayed through the live pipeline: the same texture frames colour the sets after them
    from app.commands.replay import replay_session

    replay = replay_session(str(tmp_path / "rec"))
    replayed = []
    pipe = LivePipeline(lambda: replay.make_loop(), processor, on_result=replayed.append, max_frames=10**9)
    pipe.start()
    pipe.wait()
    assert pipe.error is None and pipe.capture.refused == 0 and pipe.capture.textures == len(textures)
    assert replayed and all(set(r.frameset.frame_ids).isdisjoint(textures) for r in replayed)
    for r in replayed:
        before = [t for t in textures if t < min(r.frameset.frame_ids)]
        assert (r.texture.frame_id if r.texture is not None else None) == (before[-1] if before else None)


def test_headless_session_saves_a_textured_scan_with_its_sidecar(tmp_path, capsys):
    cfg = yaml.safe_load(open(_default_config()).read())
    cfg["sim"]["camera_size"] = [320, 240]
    path = tmp_path / "small.yaml"
    path.write_text(yaml.safe_dump(cfg))
    started = now_ns()
    out = tmp_path / "scan"
    assert main(["live", "--headless", "--config", str(path), "--frames", "40", "--out", str(out)]) == 0
    info = read_scan_info(out / "scan.yaml")
    assert info.scheme == "two-shot" and len(info.frame_ids) == 2 and info.frame_ids[1] - info.frame_ids[0] in (1, -1)
    assert info.texture_frame_id is not None and info.texture_frame_id < min(info.frame_ids)
    assert started - 1e9 <= parse_wall_clock(info.wall_clock_start, "scan.yaml") <= now_ns()
    assert info.depth_scale == 10000 and info.calibration == "calibration.yaml" and info.calibration_sha256
    depth = read_float_tiff(out / info.files["depth"])
    png = read_rgb(out / info.files["depth_png"])[..., 0]
    ok = depth > 0
    assert ok.mean() > 0.1 and np.array_equal(png > 0, ok)
    assert np.abs(png[ok] / info.depth_scale * 1000.0 - depth[ok]).max() <= 0.05 + 1e-3
    assert (out / info.files["texture"]).is_file() and (out / info.files["cloud"]).is_file()


def _default_config():
    from app.config import DEFAULT_CONFIG

    return DEFAULT_CONFIG


def test_a_texture_interval_below_two_is_one_line(tmp_path, run_cli):
    cfg = yaml.safe_load(open(_default_config()).read())
    cfg.setdefault("capture", {})["texture_every"] = 1
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(cfg))
    with pytest.raises(InputError, match=r"bad.yaml: key 'capture.texture_every' must be at least 2"):
        build_session(path)
    r = run_cli("live", "--headless", "--frames", "10", "--texture-every", "1", "--out", tmp_path / "o")
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "--texture-every 1" in lines[0], r.stderr
