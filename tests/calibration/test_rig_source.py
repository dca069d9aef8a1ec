"""The wizard's rig path: devices opened from the driver registries (the `sim` drivers, through the
same device protocol as real hardware), scripted without a window: the test's "hand" poses the
simulated board, the source films the Gray code with one checked frame per pattern, the wizard's
state keeps the poses, and the capture solves to the bench's geometry targets against the rig's truth.
Injected faults (dropped, swapped, late frames) make the pose be retaken, never saved wrong.
"""

from __future__ import annotations

import numpy as np
import pytest

from app.bench.calibration import GEOMETRY_TARGETS as TARGETS
from app.config import load_config
from calibration.auto import rig_board
from calibration.capture import CaptureWriter, open_capture
from calibration.poses import plan_poses
from calibration.response import measure_response
from calibration.rig_source import RigBoardSource
from calibration.sequence import PoseNotCapturedError, check_graycode, check_levels
from calibration.session import solve_capture
from calibration.validate import compare

RIG_YAML = """\
rig:
  camera: &sim {{driver: sim, scene: checkerboard, seed: {seed}}}
  projector: *sim
{trigger}capture:
  rate_hz: {rate}
"""


@pytest.fixture
def sim_rig(tmp_path):
    """open(seed, trigger=True, rate=30) -> (source, bench): a rig YAML of `sim` devices, opened as a rig.

    30 Hz: the simulated camera renders each frame when grabbed, and on this shared 2-core machine
    60 Hz leaves the projector thread too little time to flip before every tick.
    """
    from drivers.sim.devices import forget_shared_benches

    opened: list[RigBoardSource] = []

    def open_rig(seed: int, trigger: bool = True, rate: int = 30) -> tuple[RigBoardSource, object]:
        path = tmp_path / f"rig{seed}.yaml"
        path.write_text(RIG_YAML.format(seed=seed, trigger="  trigger: *sim\n" if trigger else "", rate=rate))
        from drivers.sim.devices import shared_bench

        bench = shared_bench(scene="checkerboard", seed=seed)  # what the registry's "sim" devices share
        src = RigBoardSource(load_config(path), rig_board(bench.rig))
        film = src._film

        def film_and_note_truth(n, check):
            # what each kept frame really saw, read before the live view reuses the frame numbers
            take = film(n, check)
            take.truth = [src.camera.truth(i) for i in take.frame_ids]
            return take

        src._film = film_and_note_truth
        opened.append(src)
        return src, bench

    yield open_rig
    for src in opened:
        src.close()
    forget_shared_benches()


def tags_true(src: RigBoardSource, take) -> bool:
    """Every kept frame saw the pattern it is filed under (the sim camera knows what each frame saw)."""
    return take.truth == list(range(len(take.frames)))


@pytest.mark.slow
def test_rig_capture_solves_to_the_targets(sim_rig, tmp_path):
    src, bench = sim_rig(seed=101)
    rig = bench.rig
    assert src.camera_size == (640, 480) and src.projector_size == (1024, 768)
    view = src.preview.wait()
    assert view is not None and view.detection is not None  # the live view sees the board
    # the wizard's state saves each kept pose with this writer (its per-pose solve is tested elsewhere)
    writer = CaptureWriter(tmp_path / "cap", src.board, src.patterns)
    # 6 poses keep this test under a minute; the 12-pose form of the same capture is
    # `slscan bench --calibration --calibration-rig 101 --calibration-poses 12 --calibration-seed 5`
    for rvec, tvec in plan_poses(src.board, rig.calibration, 6, seed=5):
        rig.set_board_pose(rvec, tvec)  # the operator's hand
        take = src.capture()
        assert tags_true(src, take)
        writer.add_pose(take.frames, timestamps_ns=take.timestamps_ns, frame_ids=take.frame_ids)
    # the capture the rig path wrote is the stable layout: --from solves it
    result = solve_capture(open_capture(tmp_path / "cap"))
    cal = result.solution.calibration
    assert result.solution.passed and cal.rms["camera_rms"] <= 0.2 and cal.rms["projector_rms"] <= 0.3
    errors = compare(cal, rig.calibration)
    for key, limit in TARGETS.items():
        assert errors[key] <= limit, (key, errors[key])
    # the dump records the camera's own frame ids, in pattern order
    dump = open_capture(tmp_path / "cap").pose_dump("pose_000")
    assert [r.pattern for r in dump.frames] == list(range(len(src.patterns)))
    ids = [r.frame_id for r in dump.frames]
    assert ids == list(range(ids[0], ids[0] + len(ids)))


@pytest.mark.slow
def test_rig_colour_levels_then_the_gray_code_again(sim_rig):
    """Colour levels filmed through the devices, then the Gray code is loaded again for the next pose."""
    from calibration.auto import fronto_pose

    src, bench = sim_rig(seed=101)
    rig = bench.rig
    # colour levels through the devices: the rig's true mixing within 0.03
    rig.set_board_pose(*fronto_pose(src.board, rig))
    levels = src.levels()
    response = measure_response(levels, camera_gamma=float(rig.options.camera_gamma))
    assert np.abs(response.color_mixing - rig.calibration.color_mixing).max() < 0.03
    assert check_levels([img for _, _, img in levels], [(c, lv) for c, lv, _ in levels]) is None
    # and the Gray code is loaded again: the next pose films fine
    assert tags_true(src, src.capture())


@pytest.mark.parametrize(
    "kind",
    [
        "drop",
        "late_flip",
        pytest.param("swap", marks=pytest.mark.slow),
        pytest.param("duplicate", marks=pytest.mark.slow),
    ],
)
def test_a_faulty_frame_makes_the_pose_be_retaken(sim_rig, kind):
    src, _ = sim_rig(seed=200 + ["drop", "swap", "late_flip", "duplicate"].index(kind))  # a fresh rig each
    n = len(src.patterns)
    # ticks restart with every trigger start: one fault in each of the first two pattern cycles
    src.camera.inject(kind, at=[5, n + 5])
    take = src.capture()
    assert tags_true(src, take)  # never saved wrong
    assert take.refused and "retaken" in take.note()
    if kind != "duplicate":  # a frame received twice is dropped alone; the others spoil their cycle
        assert take.frame_ids[0] > n + 5
    if kind == "late_flip":  # no counter saw it: the pixels did
        assert any("saw another pattern" in r for r in take.refused)


@pytest.mark.slow
def test_a_fault_on_every_cycle_gives_up_with_a_reason(sim_rig):
    src, bench = sim_rig(seed=300)
    src.camera.inject("drop", probability=0.2)
    with pytest.raises(PoseNotCapturedError, match="no clean take"):
        src.capture()
    bench.faults.clear()
    assert tags_true(src, src.capture())  # the live view came back and the next try works


def test_without_a_trigger_the_patterns_are_stepped(sim_rig):
    src, _ = sim_rig(seed=400, trigger=False)
    assert src.trigger is None
    take = src.capture()
    assert check_graycode(take.frames, src.meta) is None
    assert tags_true(src, take)
    src.camera.inject("duplicate", at=[10])  # a buffer delivered twice (frame numbers restart per start)
    again = src.capture()
    assert "arrived after" in again.note() and check_graycode(again.frames, src.meta) is None


def test_gray_code_pixel_check_catches_a_late_frame(board_rig):
    """One frame that saw its neighbour pattern (a late flip no counter saw) is refused by its pixels."""
    from core.patterns import graycode_patterns

    rig = board_rig("checkerboard", supersample=2)
    pats = graycode_patterns(rig.projector_size)
    meta = {"size": list(pats.size), **pats.params}
    from calibration.auto import fronto_pose

    rig.set_board_pose(*fronto_pose(rig_board(rig), rig))
    frames = [rig.render(img) for img in pats.images]
    assert check_graycode(frames, meta) is None
    for late in (1, 3, 8, 9, 22, 41):  # black, an inverse, a column bit, a row bit, the last one
        bad = list(frames)
        bad[late] = frames[late - 1]
        assert check_graycode(bad, meta) is not None, late
    bad = list(frames)
    bad[0] = frames[-1]  # a late white: it still shows the last pattern of the cycle before
    assert "white frame" in check_graycode(bad, meta)


def test_a_rig_without_a_board_description_is_one_line(run_cli, tmp_path):
    rig = tmp_path / "rig.yaml"
    rig.write_text(RIG_YAML.format(seed=1, trigger="", rate=30))
    proc = run_cli("calibrate", "--config", rig, "--out", tmp_path / "c.yaml")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert str(rig) in proc.stderr and "--board" in proc.stderr
    proc = run_cli("calibrate", "--config", rig, "--board", tmp_path / "nope.yaml", "--out", tmp_path / "c.yaml")
    assert proc.returncode == 2 and "nope.yaml" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
