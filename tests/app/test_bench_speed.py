"""`slscan bench --speed`: rows per compile target, judged against the decoder's targets (no timing asserted)."""

from __future__ import annotations

import json

from app.bench import speed
from app.cli import main


def test_json_rows_name_their_compile_target_and_verdict(capsys):
    argv = ["bench", "--speed", "--speed-sizes", "320x240", "--speed-repeats", "3", "--speed-targets", "native"]
    assert main([*argv, "--speed-cameras", "3ccd", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["speed"]
    assert [(r["resolution"], r["target"], r["camera"]) for r in rows] == [("320x240", "native", "3ccd")]
    row = rows[0]
    assert row["median_ms"] > 0 and row["numpy_pass_ms"] > 0
    # The three figures are rounded to 3, 3 and 2 decimals: the ratio must lie within what the rounded
    # median and numpy pass allow.
    med, base, half = row["median_ms"], row["numpy_pass_ms"], 0.0005
    assert (med - half) / (base + half) - 0.005 <= row["ratio"] <= (med + half) / max(base - half, 1e-9) + 0.005
    assert row["within_target"] is True  # no target at 320x240


def test_a_raw_rggb_row_is_judged_by_its_factor_over_the_3ccd_row(capsys):
    argv = ["bench", "--speed", "--speed-sizes", "320x240", "--speed-repeats", "3", "--speed-targets", "native"]
    assert main([*argv, "--speed-cameras", "rggb-raw", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["speed"]
    assert [r["camera"] for r in rows] == ["3ccd", "rggb-raw"]  # the 3-CCD row is always there to compare with
    ccd, raw = rows
    assert raw["median_ms"] > 0 and "x_3ccd" not in ccd
    assert abs(raw["x_3ccd"] - raw["median_ms"] / ccd["median_ms"]) <= 0.01 + 1e-3 * raw["x_3ccd"]
    assert raw["within_target"] == (raw["x_3ccd"] <= speed.MAX_RAW_FACTOR)


def test_the_verdict_follows_the_targets():
    def row(res, ms, ratio, scheme="two-shot"):
        return {"scheme": scheme, "resolution": res, "median_ms": ms, "ratio": ratio}

    assert speed.within_target(row("640x480", 2.9, 30.0))  # (no ratio target where the numpy pass is cached)
    assert not speed.within_target(row("640x480", 3.1, 5.0))
    assert speed.within_target(row("1280x1024", 9.9, 9.9))
    assert not speed.within_target(row("1280x1024", 9.9, 10.5))
    assert not speed.within_target(row("1920x1080", 30.0, 10.1))
    assert speed.within_target(row("640x480", 50.0, 99.0, scheme="graycode"))
    raw = {**row("640x480", 9.0, 40.0), "camera": "rggb-raw"}
    assert speed.within_target({**raw, "x_3ccd": 1.2}) and not speed.within_target({**raw, "x_3ccd": 1.21})


def test_an_unknown_camera_is_one_line_and_status_2(capsys):
    assert main(["bench", "--speed", "--speed-cameras", "3ccd,foveon"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "'foveon'" in err and "--speed-cameras" in err


def test_an_unknown_target_is_one_line_and_status_2(capsys):
    assert main(["bench", "--speed", "--speed-targets", "sse9"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "'sse9'" in err and "native, avx2" in err


def test_the_avx2_build_is_asked_for_without_avx512():
    features = speed.AVX2_ENV["NUMBA_CPU_FEATURES"].split(",")
    assert speed.AVX2_ENV["NUMBA_CPU_NAME"] == "haswell"
    assert "+avx2" in features and "+fma" in features
    assert not [f for f in features if "avx512" in f]
