"""The interactive calibration wizard: an operator window (pyglet, imported lazily).

Left: the live camera image with the board detection overlay (green corners; a red frame when
no board is seen) and the camera-field coverage; right: the projector-field coverage. Below:
pose count against the minimum and recommended counts, the tilt directions still missing, each
pose's error as soon as it is captured, and the verdict.

Keys: space = capture a pose, u / backspace = undo the last pose, enter = solve, verdict and a
flat-board validation scan (then s saves the calibration), q / esc = quit.
On the virtual rig the board is moved with the keyboard: n = next suggested pose, arrows = tilt,
w/a/s/d = move, z/x = nearer/farther.

So far the wizard drives the virtual rig only; on real hardware, record the poses with the
capture layout (calibration/capture.py) and solve them with `slscan calibrate --from`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from app.errors import InputError
from app.patterns import graycode_patterns
from calibration import report
from calibration.auto import fronto_pose, make_rig, rig_board
from calibration.capture import CaptureWriter
from calibration.correspondence import decode_projector_maps
from calibration.poses import plan_poses
from calibration.validate import plane_scan
from calibration.wizard_state import WizardState, overlay

PANE = (640, 480)


class SimBoardSource:
    """The virtual rig with its board moved from the keyboard (there is no hand to hold it)."""

    def __init__(self, scene: str, seed: int = 0) -> None:
        self.rig = make_rig(scene)
        self.board = rig_board(self.rig)
        self.suggested = plan_poses(self.board, self.rig.calibration, 40, seed=seed)
        self.k = 0
        self.rvec, self.tvec = fronto_pose(self.board, self.rig)
        self.patterns = graycode_patterns(self.rig.projector_size)
        self.meta = {"size": list(self.patterns.size), **self.patterns.params}
        self._prepared = None
        self._pose_changed = True
        self.rig.set_board_pose(self.rvec, self.tvec)
        w, h = self.rig.projector_size
        self._white = self.rig.prepare(np.full((h, w, 3), 255, np.uint8))

    @property
    def camera_size(self) -> tuple[int, int]:
        return self.rig.camera_size

    @property
    def projector_size(self) -> tuple[int, int]:
        return self.rig.projector_size

    def live(self) -> np.ndarray:
        return self.rig.render(self._white)

    def move(self, drot=(0.0, 0.0), dt=(0.0, 0.0, 0.0)) -> None:
        R, _ = cv2.Rodrigues(np.asarray(self.rvec, np.float64))
        pts = self.board.object_points().astype(np.float64)
        centre_b = (pts.min(0) + pts.max(0)) / 2
        centre = R @ centre_b + self.tvec
        dr, _ = cv2.Rodrigues(np.array([np.deg2rad(drot[0]), np.deg2rad(drot[1]), 0.0]))
        R = dr @ R
        centre = centre + np.asarray(dt, np.float64)
        self.rvec = cv2.Rodrigues(R)[0].ravel()
        self.tvec = centre - R @ centre_b
        self.rig.set_board_pose(self.rvec, self.tvec)

    def next_suggested(self) -> None:
        self.rvec, self.tvec = self.suggested[self.k % len(self.suggested)]
        self.k += 1
        self.rig.set_board_pose(self.rvec, self.tvec)

    def capture(self) -> list[np.ndarray]:
        if self._prepared is None:
            self._prepared = [self.rig.prepare(img) for img in self.patterns.images]
        return [self.rig.render(p) for p in self._prepared]

    def validation_scan(self, cal) -> str:
        """Scan the board held flat and facing the camera; plane-fit residual of the result."""
        self.rvec, self.tvec = fronto_pose(self.board, self.rig)
        self.rig.set_board_pose(self.rvec, self.tvec)
        column, _ = decode_projector_maps(self.capture(), self.meta)
        scan = plane_scan(column, cal, self.rig.depth_range_mm, self.rig.ground_truth.depth)
        return (
            f"validation scan of the flat board: {scan.points} points, plane-fit residual {scan.plane_rms_mm:.3f} mm, "
            f"depth error {scan.depth_error_pct:.3f} % vs truth"
        )


def run_wizard(args: argparse.Namespace) -> int:
    from app.config import load_config

    cfg = load_config(args.config)
    drivers = {cfg.get(f"rig.{k}.driver", "sim") for k in ("camera", "projector")}
    if drivers != {"sim"}:
        raise InputError(
            f"{cfg.path}: the interactive wizard drives the virtual rig only so far; record the poses as a "
            "calibration capture (board.yaml + pose_NNN/ Gray-code dumps) and run slscan calibrate --from DIR"
        )
    from drivers.projector.screens import import_pyglet

    pyglet = import_pyglet()
    from pyglet.window import key

    out = Path(args.out)
    capture_dir = Path(args.capture) if args.capture else out.with_name(out.stem + ".capture")
    src = SimBoardSource(args.scene, args.seed)
    writer = CaptureWriter(capture_dir, src.board, src.patterns)
    state = WizardState(src.board, src.camera_size, src.projector_size, writer)
    verdict: list[str] = []

    win = pyglet.window.Window(2 * PANE[0], PANE[1] + 150, caption="slscan calibrate", vsync=False)
    blank = np.zeros((PANE[1], PANE[0], 3), np.uint8)
    panes = [pyglet.image.ImageData(PANE[0], PANE[1], "RGB", blank.tobytes()) for _ in range(2)]
    text = pyglet.text.Label(
        "", x=6, y=PANE[1] + 150 - 6, width=2 * PANE[0] - 12, multiline=True, anchor_y="top", font_size=10
    )

    def upload(i: int, rgb: np.ndarray) -> None:
        rgb = cv2.resize(np.ascontiguousarray(rgb), PANE, interpolation=cv2.INTER_AREA)
        panes[i].set_data("RGB", -PANE[0] * 3, np.ascontiguousarray(rgb).tobytes())

    def coverage_image(mask: np.ndarray, size: tuple[int, int], base: np.ndarray | None = None) -> np.ndarray:
        img = base.copy() if base is not None else np.zeros((size[1], size[0], 3), np.uint8)
        tint = cv2.resize(mask.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST).astype(bool)
        img[tint] = (0.6 * img[tint] + [0, 90, 0]).astype(np.uint8)
        return img

    def refresh() -> None:
        from calibration.board import detect

        live = src.live()
        det = detect(src.board, live)
        upload(0, coverage_image(state.camera_coverage(), src.camera_size, overlay(live, det)))
        prj = coverage_image(state.projector_coverage(), src.projector_size)
        for p in state.poses:
            for x, y in p.observation.projector_points:
                cv2.circle(prj, (round(float(x)), round(float(y))), 3, (255, 255, 0), -1)
        upload(1, prj)
        seen = f"board seen ({len(det)} corners)" if det is not None else "NO BOARD in view"
        keys = (
            "space capture · u undo · enter solve · s save · n next pose · arrows tilt · wasd move · z/x depth · q quit"
        )
        text.text = "\n".join([seen, *state.hints(), *state.messages[-3:], *verdict[-3:], keys])

    @win.event
    def on_draw() -> None:
        win.clear()
        panes[0].blit(0, 0)
        panes[1].blit(PANE[0], 0)
        text.draw()

    @win.event
    def on_key_press(symbol: int, modifiers: int) -> bool:
        moves = {
            key.LEFT: ((0, -5), (0, 0, 0)), key.RIGHT: ((0, 5), (0, 0, 0)),
            key.UP: ((5, 0), (0, 0, 0)), key.DOWN: ((-5, 0), (0, 0, 0)),
            key.A: ((0, 0), (-10, 0, 0)), key.D: ((0, 0), (10, 0, 0)),
            key.W: ((0, 0), (0, -10, 0)), key.S: ((0, 0), (0, 10, 0)),
            key.Z: ((0, 0), (0, 0, -20)), key.X: ((0, 0), (0, 0, 20)),
        }  # fmt: skip
        if symbol in (key.ESCAPE, key.Q):
            pyglet.app.exit()
        elif symbol == key.SPACE:
            state.add_pose(src.capture(), src.meta, decode_projector_maps)
        elif symbol in (key.U, key.BACKSPACE):
            state.undo()
        elif symbol == key.N:
            src.next_suggested()
        elif symbol == key.ENTER:
            verdict.clear()
            if state.solution is None or state.solution.calibration is None:
                verdict.append(f"verdict: not yet: {len(state.poses)} poses")
            else:
                verdict.append(report.verdict(state.solution))
                verdict.append(src.validation_scan(state.solution.calibration))
        elif symbol == key.S and state.solution is not None and state.solution.passed:
            state.solution.calibration.save(out)
            verdict.append(f"wrote {out}")
        elif symbol in moves:
            src.move(*moves[symbol])
        else:
            return True
        refresh()
        return True

    @win.event
    def on_close() -> None:
        pyglet.app.exit()

    refresh()
    try:
        pyglet.app.run()
    except KeyboardInterrupt:
        pass
    finally:
        win.close()
    print(f"capture saved in {capture_dir} ({len(state.poses)} poses); slscan calibrate --from repeats the solve")
    return 0
