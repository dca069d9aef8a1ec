"""Bad-input sweep: malformed files of every kind the program reads, and bad arguments to every
subcommand, each through the real CLI in its own process: exit status 2, exactly one line on
stderr, never a traceback.

Speed: one runner process imports slscan once, then forks a child per case; the child runs
`app.cli.main(argv)` exactly as the `slscan` console script does (`sys.exit(main())`, an uncaught
exception prints its traceback and exits 1). A few cases are also run through the installed
`slscan` executable to show the two agree.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import yaml

from app.cli import build_parser

ROOT = Path(__file__).resolve().parents[2]
RUNNERS = 2
CASE_TIMEOUT_S = 10  # bad input is refused at once; a case still running after this accepted it

RUNNER = textwrap.dedent(
    """
    import json, os, signal, sys, time, traceback
    import numpy, cv2, yaml
    import app.cli
    app.cli.build_parser()  # imports every command module once, before the forks
    cases = json.load(open(sys.argv[1]))
    results, seconds = {}, {}
    for case in cases:
        err_path = case["err"]
        sys.stdout.flush(); sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            try:
                os.chdir(case["cwd"])
                null = os.open(os.devnull, os.O_RDWR)
                err = os.open(err_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
                os.dup2(null, 0); os.dup2(null, 1); os.dup2(err, 2)
                os.environ.pop("DISPLAY", None)
                sys.argv = ["slscan", *case["argv"]]
                try:
                    code = app.cli.main(case["argv"])
                except SystemExit as exc:
                    code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
                    if isinstance(exc.code, str):
                        print(exc.code, file=sys.stderr)
                except BaseException:
                    traceback.print_exc()
                    code = 1
                sys.stdout.flush(); sys.stderr.flush()
            finally:
                os._exit(int(code) if isinstance(code, int) else 1) if "code" in dir() else os._exit(1)
        t0 = time.monotonic()
        deadline = t0 + case.get("timeout", 30)
        while True:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                results[case["id"]] = os.waitstatus_to_exitcode(status)
                seconds[case["id"]] = round(time.monotonic() - t0, 2)
                break
            if time.monotonic() > deadline:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                results[case["id"]] = "timeout"
                seconds[case["id"]] = round(time.monotonic() - t0, 2)
                break
            time.sleep(0.005)
    json.dump({"codes": results, "seconds": seconds}, open(sys.argv[2], "w"))
    """
)


# ------------------------------------------------------------------------------------ the inputs


def _base_dump(root: Path) -> Path:
    """A small valid dump (2 frames, 160x120) from the virtual rig, made through the CLI."""
    base = root / "base"
    cmd = [sys.executable, "-m", "app.cli", "sim", "render", "--scene", "face", "--scheme", "two-shot", "--ideal"]
    subprocess.run([*cmd, "--camera-size", "160x120", "--out", str(base)], check=True, capture_output=True, cwd=ROOT)
    return base


class Cases:
    def __init__(self, root: Path, base: Path) -> None:
        self.root, self.base = root, base
        self.table: dict[str, list[str]] = {}
        self.sim_cfg = yaml.safe_load((ROOT / "config" / "sim.yaml").read_text())

    def add(self, cid: str, *argv: object) -> None:
        assert cid not in self.table, cid
        self.table[cid] = [str(a) for a in argv]

    def file(self, name: str, content: str | bytes) -> Path:
        p = self.root / "files" / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(content.encode() if isinstance(content, str) else content)
        return p

    def dump(self, name: str, edit) -> Path:
        """A copy of the base dump changed by edit(folder)."""
        d = self.root / "dumps" / name
        shutil.copytree(self.base, d)
        edit(d)
        return d

    def out(self, name: str) -> Path:
        return self.root / "out" / name  # never created beforehand


def _set_index(d: Path, change) -> None:
    meta = yaml.safe_load((d / "dump.yaml").read_text())
    change(meta)
    (d / "dump.yaml").write_text(yaml.safe_dump(meta, sort_keys=False))


def _frame(d: Path, i: int) -> Path:
    return d / "frames" / f"{i:06d}.png"


def _write_png(path: Path, image: np.ndarray) -> None:
    import cv2

    ok, buf = cv2.imencode(".png", image)
    assert ok
    path.write_bytes(buf.tobytes())


def build_cases(root: Path, base: Path | None = None) -> Cases:
    """Every case: id -> argv, with its files written under root (base: a valid dump to mutate)."""
    c = Cases(root, base or _base_dump(root))

    # --- config YAML (slscan dump / live read it before opening any device)
    def cfg(name: str, data: object | None = None, text: str | bytes | None = None) -> Path:
        return c.file(f"{name}.yaml", text if text is not None else yaml.safe_dump(data))

    def sim_with(**sim) -> dict:
        return {**c.sim_cfg, "sim": {**c.sim_cfg["sim"], **sim}}

    configs = {
        "cfg_not_yaml": cfg("not_yaml", text="rig: [camera\n  driver: : sim\n"),
        "cfg_empty": cfg("empty", text=""),
        "cfg_binary": cfg("binary", text=bytes(range(256))),
        "cfg_list": cfg("list", ["rig", "sim"]),
        "cfg_no_rig": cfg("no_rig", {"sim": c.sim_cfg["sim"]}),
        "cfg_unknown_driver": cfg(
            "unknown_driver", {**c.sim_cfg, "rig": {**c.sim_cfg["rig"], "camera": {"driver": "nope"}}}
        ),
        "cfg_camera_not_mapping": cfg("cam_str", {**c.sim_cfg, "rig": {**c.sim_cfg["rig"], "camera": "sim"}}),
        "cfg_rate_string": cfg("rate_str", {**c.sim_cfg, "capture": {"rate_hz": "fast"}}),
        "cfg_rate_zero": cfg("rate_zero", {**c.sim_cfg, "capture": {"rate_hz": 0}}),
        "cfg_scheme_unknown": cfg("scheme", {**c.sim_cfg, "scheme": {"name": "three-shot"}}),
        "cfg_scheme_k_string": cfg("k_str", {**c.sim_cfg, "scheme": {**c.sim_cfg["scheme"], "k": "seven"}}),
        "cfg_depth_range_reversed": cfg("depth_rev", {**c.sim_cfg, "depth_range_mm": [1200, 400]}),
        "cfg_sim_camera_size_bad": cfg("cam_size", sim_with(camera_size=[0, -5])),
        "cfg_sim_camera_size_string": cfg("cam_size_str", sim_with(camera_size="640x480")),
        "cfg_sim_scene_unknown": cfg("scene_unknown", sim_with(scene="no-such-scene")),
        "cfg_sim_faults_bad": cfg("faults", sim_with(faults=[{"kind": "explode", "at": 3}])),
        "cfg_sim_seed_string": cfg("seed", sim_with(seed="abc")),
        "cfg_sim_seed_negative": cfg("seed_neg", sim_with(seed=-1)),
        "cfg_sim_buffer_zero": cfg("buffer", sim_with(buffer_frames=0)),
        "cfg_sim_effects_unknown": cfg("effects", sim_with(effects={"warp_drive": 1})),
        "cfg_missing_file": c.root / "files" / "missing.yaml",
        "cfg_is_directory": c.root / "files",
    }
    for cid, path in configs.items():
        c.add(f"dump:{cid}", "dump", "--config", path, "--frames", "2", "--out", c.out(cid))
    c.add("live:cfg_not_yaml", "live", "--headless", "--frames", "2", "--config", configs["cfg_not_yaml"])
    c.add("grab:cfg_unknown_driver", "grab", "--config", configs["cfg_unknown_driver"], "--out", c.out("grab"))

    # --- calibration YAML (decode --calibration)
    good_cal = (c.base / "calibration.yaml").read_text()
    cals = {
        "cal_not_filestorage": "just: [some, yaml]\n",
        "cal_empty": "",
        "cal_binary": bytes(range(256)) * 4,
        "cal_no_camera_matrix": re.sub(r"camera_matrix: !!opencv-matrix\n(   .*\n)+", "", good_cal, count=1),
        "cal_matrix_2x2": good_cal.replace(
            "   rows: 3\n   cols: 3\n   dt: d\n   data: [ 550.", "   rows: 2\n   cols: 2\n   dt: d\n   data: [ 550.", 1
        ).replace("0., 550., 80.224999999999994, 0., 550., 58.649999999999999,\n       0., 0., 1. ]", "0., 550. ]"),
        "cal_nan": good_cal.replace("550., 0., 80.2", ".nan, 0., 80.2", 1),
        "cal_truncated": good_cal[: len(good_cal) // 2],
    }
    for cid, text in cals.items():
        path = c.file(f"{cid}.yaml", text)
        c.add(f"decode:{cid}", "decode", c.base, "--calibration", path, "--out", c.out(cid))
    c.add("decode:cal_missing", "decode", c.base, "--calibration", c.root / "nope.yaml", "--out", c.out("calm"))
    c.add(
        "replay:cal_not_filestorage",
        "replay",
        c.base,
        "--headless",
        "--calibration",
        c.root / "files" / "cal_not_filestorage.yaml",
        "--out",
        c.out("rcal"),
    )

    # --- dump.yaml
    def index_case(cid: str, change) -> None:
        d = c.dump(cid, lambda d: _set_index(d, change))
        c.add(f"decode:{cid}", "decode", d, "--out", c.out(cid))

    index_case("dump_format_wrong", lambda m: m.update(format="other"))
    index_case("dump_version_2", lambda m: m.update(version=2))
    index_case("dump_no_scheme", lambda m: m.pop("scheme", None))
    index_case("dump_scheme_unknown", lambda m: m.update(scheme="three-shot"))
    index_case("dump_patterns_escape", lambda m: m.update(patterns="../../etc"))
    index_case("dump_patterns_absolute", lambda m: m.update(patterns="/etc"))
    index_case("dump_calibration_escape", lambda m: m.update(calibration="../base/calibration.yaml"))
    index_case("dump_calibration_absolute", lambda m: m.update(calibration=str(c.base / "calibration.yaml")))
    index_case("dump_frame_escape", lambda m: m["frames"][0].update(file="../../base/frames/000000.png"))
    index_case("dump_frame_absolute", lambda m: m["frames"][0].update(file=str(_frame(c.base, 0))))
    index_case("dump_frames_not_list", lambda m: m.update(frames={"a": 1}))
    index_case("dump_frame_missing_field", lambda m: m["frames"][0].pop("frame_id", None))
    index_case("dump_frame_id_string", lambda m: m["frames"][0].update(frame_id="one"))
    index_case("dump_pattern_negative", lambda m: m["frames"][0].update(pattern=-1))
    index_case("dump_pattern_out_of_scheme", lambda m: m["frames"][0].update(pattern=7))
    index_case("dump_depth_range_bad", lambda m: m.update(depth_range_mm=[900, "far"]))
    index_case("dump_no_frames", lambda m: m.update(frames=[]))
    for cid, text in {
        "dump_index_not_yaml": "format: slscan-dump\nversion: [1\n",
        "dump_index_list": "- 1\n- 2\n",
        "dump_index_binary": bytes(range(256)).decode("latin-1"),
    }.items():
        d = c.dump(cid, lambda d, t=text: (d / "dump.yaml").write_text(t))
        c.add(f"decode:{cid}", "decode", d, "--out", c.out(cid))
    d = c.dump("dump_first_frame_missing", lambda d: _frame(d, 0).unlink())
    c.add("decode:dump_first_frame_missing", "decode", d, "--out", c.out("ffm"))
    c.add("decode:dump_missing", "decode", c.root / "no-dump", "--out", c.out("nodump"))
    c.add(
        "replay:dump_patterns_escape",
        "replay",
        c.root / "dumps" / "dump_patterns_escape",
        "--headless",
        "--out",
        c.out("rpe"),
    )

    # --- frame PNGs
    def png_case(cid: str, edit) -> None:
        d = c.dump(cid, edit)
        c.add(f"decode:{cid}", "decode", d, "--out", c.out(cid))

    png_case("png_truncated", lambda d: _frame(d, 0).write_bytes(_frame(d, 0).read_bytes()[:300]))
    png_case("png_empty", lambda d: _frame(d, 1).write_bytes(b""))
    png_case("png_text", lambda d: _frame(d, 0).write_text("not a png"))
    png_case("png_wrong_size", lambda d: _write_png(_frame(d, 1), np.zeros((60, 80, 3), np.uint8)))
    png_case("png_16bit_mixed", lambda d: _write_png(_frame(d, 1), np.zeros((120, 160, 3), np.uint16)))
    png_case("png_1x1", lambda d: _write_png(_frame(d, 0), np.zeros((1, 1, 3), np.uint8)))

    # --- patterns.yaml and pattern images (inside a dump)
    def pat_case(cid: str, change=None, edit=None) -> None:
        def go(d: Path) -> None:
            if change is not None:
                meta = yaml.safe_load((d / "patterns" / "patterns.yaml").read_text())
                change(meta)
                (d / "patterns" / "patterns.yaml").write_text(yaml.safe_dump(meta))
            if edit is not None:
                edit(d)

        png_case(cid, go)

    pat_case("patterns_scheme_unknown", lambda m: m.update(scheme="x"))
    pat_case("patterns_size_bad", lambda m: m.update(size=[0, "a"]))
    pat_case("patterns_k_string", lambda m: m.update(k="seven"))
    pat_case("patterns_image_escape", lambda m: m.update(images=["../../../base/patterns/frame1.png", "frame2.png"]))
    pat_case("patterns_sequence_bad", lambda m: m.update(sequence=[9, 9, 9]))
    pat_case("patterns_channels_bad", lambda m: m.update(channels="QQ"))
    pat_case("patterns_no_file", edit=lambda d: (d / "patterns" / "patterns.yaml").unlink())
    pat_case("patterns_not_yaml", edit=lambda d: (d / "patterns" / "patterns.yaml").write_text("scheme: [\n"))

    # --- board.yaml (calibrate --from a capture folder)
    boards = {
        "board_not_yaml": "type: [checkerboard\n",
        "board_list": "- 1\n",
        "board_type_unknown": "type: hexagon\nrows: 6\ncols: 9\nsquare_mm: 20\n",
        "board_missing_rows": "type: checkerboard\ncols: 9\nsquare_mm: 20\n",
        "board_rows_string": "type: checkerboard\nrows: six\ncols: 9\nsquare_mm: 20\n",
        "board_square_negative": "type: checkerboard\nrows: 6\ncols: 9\nsquare_mm: -20\n",
        "board_charuco_bad_dictionary": "type: charuco\nrows: 6\ncols: 9\nsquare_mm: 20\nmarker_mm: 15\n"
        "dictionary: NOPE\n",
        "board_unknown_field": "type: checkerboard\nrows: 6\ncols: 9\nsquare_mm: 20\ncolour: red\n",
    }
    for cid, text in boards.items():
        folder = c.root / "captures" / cid
        folder.mkdir(parents=True)
        (folder / "board.yaml").write_text(text)
        c.add(f"calibrate:{cid}", "calibrate", "--from", folder, "--out", c.out(cid) / "cal.yaml")
    folder = c.root / "captures" / "board_ok_no_poses"
    folder.mkdir(parents=True)
    (folder / "board.yaml").write_text("type: checkerboard\nrows: 6\ncols: 9\nsquare_mm: 20\n")
    c.add("calibrate:capture_without_poses", "calibrate", "--from", folder, "--out", c.out("nop") / "cal.yaml")

    # --- scene YAML (sim render --scene FILE)
    head = "depth_range_mm: [600, 900]\nobjects:\n"
    scenes = {
        "scene_not_yaml": "objects: [\n",
        "scene_list": "- plane\n",
        "scene_no_objects": "description: nothing\ndepth_range_mm: [600, 900]\n",
        "scene_object_type_unknown": head + "  - {type: dragon, center: [0, 0, 700]}\n",
        "scene_center_string": head + "  - {type: plane, center: here, size: [100, 100]}\n",
        "scene_depth_range_bad": head.replace("[600, 900]", "[900]") + "  - {type: plane, center: [0, 0, 800]}\n",
    }
    for cid, text in scenes.items():
        path = c.file(f"{cid}.yaml", text)
        c.add(f"sim:{cid}", "sim", "render", "--scene", path, "--scheme", "two-shot", "--out", c.out(cid))
    c.add(
        "sim:scene_missing_file",
        "sim",
        "render",
        "--scene",
        c.root / "nope.yaml",
        "--scheme",
        "two-shot",
        "--out",
        c.out("scm"),
    )

    # --- CLI arguments: every typed option of every subcommand given a value of the wrong type
    for name, sub in _subparsers().items():
        for act in sub._actions:
            numeric = act.type in (int, float) or getattr(act.type, "__module__", "") == "app.argtypes"
            if act.option_strings and numeric:
                opt = act.option_strings[-1]
                c.add(f"args:{name} {opt} abc", name, opt, "abc")
            if act.option_strings and act.choices and act.nargs is None:
                c.add(f"args:{name} {act.option_strings[-1]} bogus", name, act.option_strings[-1], "bogus-choice")
        c.add(f"args:{name} --no-such-option", name, "--no-such-option")
    c.add("args:unknown command", "frobnicate")
    # values of the right type that make no sense
    out = c.out
    for cid, argv in {
        "dump --frames 0": ["dump", "--frames", "0", "--out", out("f0")],
        "dump --frames -3": ["dump", "--frames", "-3", "--out", out("fm3")],
        "dump --png-level 12": ["dump", "--frames", "2", "--png-level", "12", "--out", out("png12")],
        "dump --timeout -1": ["dump", "--frames", "2", "--timeout", "-1", "--out", out("tm1")],
        "dump without --out": ["dump", "--frames", "2"],
        "dump --out existing dump": ["dump", "--frames", "2", "--out", c.base],
        "dump --repair not a dump": ["dump", "--repair", c.root / "files"],
        "live --frames 0": ["live", "--headless", "--frames", "0"],
        "live --workers 0": ["live", "--headless", "--frames", "2", "--workers", "0"],
        "live --png-level -1": ["live", "--headless", "--frames", "2", "--png-level", "-1", "--record", out("lr")],
        "live --timeout 0": ["live", "--headless", "--frames", "2", "--timeout", "0"],
        "decode --workers -1": ["decode", c.base, "--workers", "-1", "--out", out("dw0")],
        "decode --out is a file": ["decode", c.base, "--out", c.base / "dump.yaml"],
        "replay --frames 0": ["replay", c.base, "--headless", "--frames", "0", "--out", out("rf0")],
        "replay --workers -2": ["replay", c.base, "--headless", "--workers", "-2", "--out", out("rw")],
        "patterns --size 10x": ["patterns", "--scheme", "two-shot", "--size", "10x", "--out", out("ps")],
        "patterns --size 0x0": ["patterns", "--scheme", "two-shot", "--size", "0x0", "--out", out("ps0")],
        "patterns --k 99": ["patterns", "--scheme", "two-shot", "--size", "64x48", "--k", "99", "--out", out("pk")],
        "patterns --stripe-width 0": [
            "patterns",
            "--scheme",
            "two-shot",
            "--size",
            "64x48",
            "--stripe-width",
            "0",
            "--out",
            out("psw"),
        ],
        "patterns --channels QQ": [
            "patterns",
            "--scheme",
            "two-shot",
            "--size",
            "64x48",
            "--channels",
            "QQ",
            "--out",
            out("pch"),
        ],
        "patterns --colors Z": [
            "patterns",
            "--scheme",
            "one-shot",
            "--size",
            "64x48",
            "--colors",
            "Z",
            "--out",
            out("pco"),
        ],
        "project --hz 0": ["project", "--scheme", "two-shot", "--hz", "0"],
        "project --size abc": ["project", "--scheme", "two-shot", "--size", "abc"],
        "project --gamma -1": ["project", "--scheme", "two-shot", "--gamma", "-1"],
        "sim render --camera-size 0x0": [
            "sim",
            "render",
            "--scene",
            "face",
            "--scheme",
            "two-shot",
            "--camera-size",
            "0x0",
            "--out",
            out("s00"),
        ],
        "sim render --cycles 0": [
            "sim",
            "render",
            "--scene",
            "face",
            "--scheme",
            "two-shot",
            "--cycles",
            "0",
            "--out",
            out("sc0"),
        ],
        "sim render --seed -1": [
            "sim",
            "render",
            "--scene",
            "face",
            "--scheme",
            "two-shot",
            "--seed",
            "-1",
            "--out",
            out("ss"),
        ],
        "sim render --k 99": [
            "sim",
            "render",
            "--scene",
            "face",
            "--scheme",
            "two-shot",
            "--k",
            "99",
            "--out",
            out("sk"),
        ],
        "calibrate --poses 0": ["calibrate", "--auto", "--poses", "0", "--out", out("cp") / "c.yaml"],
        "calibrate --seed -1": ["calibrate", "--auto", "--poses", "3", "--seed", "-1", "--out", out("cs") / "c.yaml"],
        "calibrate --scene unknown": ["calibrate", "--auto", "--scene", "nope", "--out", out("csc") / "c.yaml"],
        "grab --frames 0": ["grab", "--frames", "0", "--out", out("g0")],
        "grab --camera unknown": ["grab", "--camera", "nosuch:cam", "--frames", "1", "--out", out("gc")],
        "bench --minutes -1": ["bench", "--soak", "--minutes", "-1"],
        "bench --live-frames 0": ["bench", "--live", "--live-frames", "0"],
        "bench --speed-schemes bogus": ["bench", "--speed", "--speed-schemes", "bogus"],
        "bench --calibration-poses 0": ["bench", "--calibration", "--calibration-poses", "0"],
        "bench --render-frames 0": ["bench", "--render", "--render-frames", "0"],
        "bench --accuracy-scenes nope": ["bench", "--accuracy", "--accuracy-scenes", "nope"],
    }.items():
        c.add(f"args:{cid}", *argv)
    return c


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    subs: dict[str, argparse.ArgumentParser] = {}
    for act in parser._actions:
        if isinstance(act, argparse._SubParsersAction):
            for name, sub in act.choices.items():
                subs[name] = sub
                for inner in sub._actions:  # slscan sim render / scenes
                    if isinstance(inner, argparse._SubParsersAction):
                        for n2, s2 in inner.choices.items():
                            subs[f"{name} {n2}"] = s2
    return subs


# ------------------------------------------------------------------------------------ running them


@pytest.fixture(scope="module")
def sweep(tmp_path_factory, rig_session) -> tuple[dict, dict, dict]:
    # rig_session has compiled the two-shot decoder into numba's cache (tests/reliability/conftest.py): `slscan live`
    # opens its recorder, and so checks --png-level, only after the decoder's warm-up, which on an empty cache
    # prints "compiling ..." and takes about a minute (app/commands/live.py); the cases time the refusal, not that.
    root = tmp_path_factory.mktemp("sweep")
    cases = build_cases(root)
    errs = root / "stderr"
    errs.mkdir()
    spec = []
    for i, (cid, argv) in enumerate(cases.table.items()):
        spec.append(
            {
                "id": cid,
                "argv": argv[0].split() + argv[1:] if argv[0].startswith("sim ") else argv,
                "err": str(errs / f"{i}.txt"),
                "cwd": str(root),
                "timeout": CASE_TIMEOUT_S,
            }
        )
    # two runners, one per core: most cases spend their time starting up, not computing
    procs = []
    for k in range(RUNNERS):
        (root / f"cases{k}.json").write_text(json.dumps(spec[k::RUNNERS]))
        argv = [sys.executable, "-c", RUNNER, str(root / f"cases{k}.json"), str(root / f"codes{k}.json")]
        procs.append(subprocess.Popen(argv, cwd=ROOT))
    codes: dict = {}
    for k, proc in enumerate(procs):
        assert proc.wait(timeout=900) == 0
        codes.update(json.loads((root / f"codes{k}.json").read_text())["codes"])
    stderr = {s["id"]: Path(s["err"]).read_text(errors="replace") for s in spec}
    return cases.table, codes, stderr


def _case_ids() -> list[str]:
    """The case ids at collection time, from the same table builder over a stand-in dump (no slscan run)."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        base = root / "base"
        base.mkdir()
        # the ids do not depend on the base dump's contents: a minimal stand-in for collection
        (base / "calibration.yaml").write_text("")
        (base / "dump.yaml").write_text("frames: [{file: frames/000000.png}, {file: frames/000001.png}]\n")
        (base / "patterns").mkdir()
        (base / "patterns" / "patterns.yaml").write_text("scheme: two-shot\n")
        (base / "frames").mkdir()
        for i in range(2):
            (base / "frames" / f"{i:06d}.png").write_bytes(b"")
        return list(build_cases(root, base).table)


@pytest.mark.parametrize("cid", _case_ids())
def test_bad_input_is_one_line_and_exit_2(sweep, cid):
    table, codes, stderr = sweep
    err = stderr[cid]
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err, f"slscan {' '.join(table[cid])}\n{err}"
    assert codes[cid] == 2 and len(lines) == 1, f"exit {codes[cid]}, slscan {' '.join(table[cid])}\n{err}"


def test_the_installed_slscan_agrees_with_the_runner(sweep):
    table, codes, stderr = sweep
    for cid in ("dump:cfg_not_yaml", "decode:dump_patterns_escape", "args:dump --frames abc"):
        proc = subprocess.run(["slscan", *table[cid]], capture_output=True, text=True, cwd=ROOT, timeout=60)
        assert (proc.returncode, proc.stderr) == (codes[cid], stderr[cid])


def test_only_yaml_safe_load_is_used():
    bad = re.compile(r"yaml\.(load|unsafe_load|full_load|load_all|unsafe_load_all)\(|yaml\.(Unsafe|Full)?Loader\b")
    hits = []
    for pkg in ("app", "drivers", "calibration"):
        for path in (ROOT / pkg).rglob("*.py"):
            for n, line in enumerate(path.read_text().splitlines(), 1):
                if bad.search(line):
                    hits.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()}")
    assert hits == []
