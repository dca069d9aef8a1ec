"""The interactive calibration wizard: an operator window (pyglet, imported lazily).

Left: the live camera image with the board detection overlay (green corners; a red frame when
no board is seen) and the camera-field coverage; right: the projector-field coverage. Below:
pose count against the minimum and recommended counts, the tilt directions still missing, each
pose's error as soon as it is captured, and the verdict.

Keys: space = capture a pose, u / backspace = undo the last pose, c = colour response (flat
levels per channel: curves, colour mixing, a warning when a channel is nearly saturated or too
dark), enter = verdict and a flat-board validation scan, s = save the calibration (once the solve
passes), q / esc = quit.
On the virtual rig the board is moved with the keyboard: n = next suggested pose, f = flat and
facing the camera, arrows = tilt,
i/j/k/l = move, z/x = nearer/farther.

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
from calibration.response import Response, level_image, level_plan, measure_response
from calibration.validate import plane_scan
from calibration.wizard_state import WizardState, overlay

PANE = (640, 480)


class SimBoardSource:
    """The virtual rig with its board moved from the keyboard (there is no hand to hold it)."""

    def __init__(self, scene: str, seed: int = 0, **rig_overrides: object) -> None:
        self.rig = make_rig(scene, **rig_overrides)
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

    def flat(self) -> None:
        """The board facing the camera in the middle of the working range (colour levels, validation)."""
        self.rvec, self.tvec = fronto_pose(self.board, self.rig)
        self.rig.set_board_pose(self.rvec, self.tvec)

    def next_suggested(self) -> None:
        self.rvec, self.tvec = self.suggested[self.k % len(self.suggested)]
        self.k += 1
        self.rig.set_board_pose(self.rvec, self.tvec)

    def capture(self) -> list[np.ndarray]:
        if self._prepared is None:
            self._prepared = [self.rig.prepare(img) for img in self.patterns.images]
        return [self.rig.render(p) for p in self._prepared]

    def levels(self) -> list[tuple[str, int, np.ndarray]]:
        """Flat colour levels per channel on the board held where it is."""
        return [(ch, lv, self.rig.render(level_image(self.projector_size, ch, lv))) for ch, lv in level_plan()]

    @property
    def camera_gamma(self) -> float:
        return float(self.rig.options.camera_gamma)

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


class WizardWindow:
    """The operator window over a board source; keys go through `handle_key` (scriptable in tests)."""

    def __init__(self, src: SimBoardSource, out: Path, capture_dir: Path) -> None:
        from drivers.projector.screens import display_name, import_pyglet

        display_name()  # a clear one-line error without a display, before pyglet tries
        self.pyglet = pyglet = import_pyglet()
        from pyglet.window import key

        self.key = key
        self.src, self.out, self.capture_dir = src, out, capture_dir
        writer = CaptureWriter(capture_dir, src.board, src.patterns)
        self.state = WizardState(src.board, src.camera_size, src.projector_size, writer)
        self.verdict: list[str] = []
        self.response: Response | None = None
        self.win = pyglet.window.Window(2 * PANE[0], PANE[1] + 150, caption="slscan calibrate", vsync=False)
        blank = np.zeros((PANE[1], PANE[0], 3), np.uint8)
        self.panes = [pyglet.image.ImageData(PANE[0], PANE[1], "RGB", blank.tobytes()) for _ in range(2)]
        self.label = pyglet.text.Label(
            "", x=6, y=PANE[1] + 150 - 6, width=2 * PANE[0] - 12, multiline=True, anchor_y="top", font_size=10
        )
        self.moves = {
            key.LEFT: ((0, -5), (0, 0, 0)), key.RIGHT: ((0, 5), (0, 0, 0)),
            key.UP: ((5, 0), (0, 0, 0)), key.DOWN: ((-5, 0), (0, 0, 0)),
            key.J: ((0, 0), (-10, 0, 0)), key.L: ((0, 0), (10, 0, 0)),
            key.I: ((0, 0), (0, -10, 0)), key.K: ((0, 0), (0, 10, 0)),
            key.Z: ((0, 0), (0, 0, -20)), key.X: ((0, 0), (0, 0, 20)),
        }  # fmt: skip
        self.win.push_handlers(on_draw=self.on_draw, on_key_press=self.on_key_press, on_close=self.on_close)
        self.refresh()

    def upload(self, i: int, rgb: np.ndarray) -> None:
        rgb = cv2.resize(np.ascontiguousarray(rgb), PANE, interpolation=cv2.INTER_AREA)
        self.panes[i].set_data("RGB", -PANE[0] * 3, np.ascontiguousarray(rgb).tobytes())

    @staticmethod
    def coverage_image(mask: np.ndarray, size: tuple[int, int], base: np.ndarray | None = None) -> np.ndarray:
        img = base.copy() if base is not None else np.zeros((size[1], size[0], 3), np.uint8)
        tint = cv2.resize(mask.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST).astype(bool)
        img[tint] = (0.6 * img[tint] + [0, 90, 0]).astype(np.uint8)
        return img

    def refresh(self) -> None:
        from calibration.board import detect

        src, state = self.src, self.state
        live = src.live()
        det = detect(src.board, live)
        self.upload(0, self.coverage_image(state.camera_coverage(), src.camera_size, overlay(live, det)))
        prj = self.coverage_image(state.projector_coverage(), src.projector_size)
        for p in state.poses:
            for x, y in p.observation.projector_points:
                cv2.circle(prj, (round(float(x)), round(float(y))), 3, (255, 255, 0), -1)
        self.upload(1, prj)
        seen = f"board seen ({len(det)} corners)" if det is not None else "NO BOARD in view"
        keys = (
            "space capture · u undo · c colour · enter verdict · s save · "
            "n next pose · f flat · arrows tilt · ijkl move · z/x depth · q quit"
        )
        self.label.text = "\n".join([seen, *state.hints(), *state.messages[-3:], *self.verdict[-4:], keys])

    def handle_key(self, symbol: int) -> None:
        key, state, src = self.key, self.state, self.src
        if symbol == key.SPACE:
            state.add_pose(src.capture(), src.meta, decode_projector_maps)
        elif symbol in (key.U, key.BACKSPACE):
            state.undo()
        elif symbol == key.N:
            src.next_suggested()
        elif symbol == key.F:
            src.flat()
        elif symbol == key.ENTER:
            self.verdict.clear()
            if state.solution is None or state.solution.calibration is None:
                self.verdict.append(f"verdict: not yet: {len(state.poses)} poses")
            else:
                self.verdict.append(report.verdict(state.solution))
                self.verdict.append(src.validation_scan(state.solution.calibration))
        elif symbol == key.C:
            self.measure_colour()
        elif symbol == key.S:
            if state.solution is not None and state.solution.passed:
                cal = state.solution.calibration
                if self.response is not None:
                    cal.color_mixing = self.response.color_mixing
                    cal.extra.update(self.response.as_extra())
                    cal.extra["camera_gamma"] = self.src.camera_gamma
                cal.save(self.out)
                self.verdict.append(f"wrote {self.out}")
            else:
                self.verdict.append("not saved: the solve has not passed its checks yet")
        elif symbol in self.moves:
            src.move(*self.moves[symbol])
        else:
            return
        self.refresh()

    def measure_colour(self) -> None:
        """Flat levels per channel: response curves, colour mixing, saturation / darkness warnings."""
        import shutil

        from calibration.capture import RESPONSE_DIR

        levels = self.src.levels()
        try:
            self.response = measure_response(levels, camera_gamma=self.src.camera_gamma)
        except ValueError as exc:
            self.verdict.append(f"colour response: {exc}")
            return
        writer = self.state.writer
        if writer is not None:
            shutil.rmtree(writer.folder / RESPONSE_DIR, ignore_errors=True)  # the latest measurement wins
            writer.write_response(levels, camera_gamma=self.src.camera_gamma)
        self.verdict.extend(report.response_text(self.response).splitlines())

    def on_draw(self) -> None:
        self.win.clear()
        self.panes[0].blit(0, 0)
        self.panes[1].blit(PANE[0], 0)
        self.label.draw()

    def on_key_press(self, symbol: int, modifiers: int) -> bool:
        if symbol in (self.key.ESCAPE, self.key.Q):
            self.pyglet.app.exit()
        else:
            self.handle_key(symbol)
        return True

    def on_close(self) -> None:
        self.pyglet.app.exit()

    def close(self) -> None:
        self.win.close()

    def run(self) -> None:
        try:
            self.pyglet.app.run()
        except KeyboardInterrupt:
            pass
        finally:
            self.close()


def run_wizard(args: argparse.Namespace) -> int:
    from app.config import load_config

    cfg = load_config(args.config)
    drivers = {cfg.get(f"rig.{k}.driver", "sim") for k in ("camera", "projector")}
    if drivers != {"sim"}:
        raise InputError(
            f"{cfg.path}: the interactive wizard drives the virtual rig only so far; record the poses as a "
            "calibration capture (board.yaml + pose_NNN/ Gray-code dumps) and run slscan calibrate --from DIR"
        )
    from drivers.projector.screens import display_name

    display_name()  # no display: one clear line before minutes of rig set-up
    out = Path(args.out)
    capture_dir = Path(args.capture) if args.capture else out.with_name(out.stem + ".capture")
    window = WizardWindow(SimBoardSource(args.scene, args.seed), out, capture_dir)
    window.run()
    n = len(window.state.poses)
    print(f"capture saved in {capture_dir} ({n} poses); slscan calibrate --from {capture_dir} repeats the solve")
    return 0
