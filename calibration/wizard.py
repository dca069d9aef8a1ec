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
facing the camera, arrows = tilt, i/j/k/l = move, z/x = nearer/farther.

The window drives a board source (calibration/source.py): the virtual rig with its keyboard-moved
board, or a rig opened from the driver registries (calibration/rig_source.py: real devices, or
the `sim` drivers through the same device protocol). The live view comes from the source's
preview worker, off the UI thread; the window polls it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from calibration import report
from calibration.capture import CaptureWriter
from calibration.correspondence import decode_projector_maps
from calibration.response import Response, measure_response
from calibration.sim_source import SimBoardSource
from calibration.source import BoardSource
from calibration.wizard_state import WizardState, overlay
from core.errors import DeviceError, InputError

__all__ = ["SimBoardSource", "WizardWindow", "run_wizard"]

PANE = (640, 480)
POLL_S = 1 / 20  # how often the window looks for a new live view


class WizardWindow:
    """The operator window over a board source; keys go through `handle_key` (scriptable in tests)."""

    def __init__(self, src: BoardSource, out: Path, capture_dir: Path) -> None:
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
        self.shown = 0  # the preview view on screen (its seq)
        caption = f"slscan calibrate: {src.name}"
        self.win = pyglet.window.Window(2 * PANE[0], PANE[1] + 150, caption=caption, vsync=False)
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
        if not src.movable:
            self.moves = {}
        self.win.push_handlers(on_draw=self.on_draw, on_key_press=self.on_key_press, on_close=self.on_close)
        self.quit = False
        self.refresh()

    def poll(self) -> bool:
        """Show a new live view if the preview worker has one; True if it did."""
        view = self.src.preview.latest()
        if view is None or view.seq == self.shown:
            return False
        self.refresh()
        return True

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
        """Redraw both panes and the text from the newest live view and the state."""
        src, state = self.src, self.state
        view = src.preview.latest()
        if view is not None:
            self.shown = view.seq
            live, det = view.image, view.detection
        else:
            live, det = np.zeros((src.camera_size[1], src.camera_size[0], 3), np.uint8), None
        self.upload(0, self.coverage_image(state.camera_coverage(), src.camera_size, overlay(live, det)))
        prj = self.coverage_image(state.projector_coverage(), src.projector_size)
        for p in state.poses:
            for x, y in p.observation.projector_points:
                cv2.circle(prj, (round(float(x)), round(float(y))), 3, (255, 255, 0), -1)
        self.upload(1, prj)
        seen = f"board seen ({len(det)} corners)" if det is not None else "NO BOARD in view"
        if view is None:
            seen = "waiting for the camera..."
        if src.preview.error:
            seen += f" · {src.preview.error}"
        keys = "space capture · u undo · c colour · enter verdict · s save · q quit"
        if src.movable:
            keys += " · n next pose · f flat · arrows tilt · ijkl move · z/x depth"
        self.label.text = "\n".join([seen, *state.hints(), *state.messages[-3:], *self.verdict[-4:], keys])

    def handle_key(self, symbol: int) -> None:
        key, state, src = self.key, self.state, self.src
        if symbol == key.SPACE:
            self.capture_pose()
        elif symbol in (key.U, key.BACKSPACE):
            state.undo()
        elif symbol == key.N and src.movable:
            src.next_suggested()  # type: ignore[attr-defined]
        elif symbol == key.F and src.movable:
            src.flat()  # type: ignore[attr-defined]
        elif symbol == key.ENTER:
            self.verdict.clear()
            if state.solution is None or state.solution.calibration is None:
                self.verdict.append(f"verdict: not yet: {len(state.poses)} poses")
            else:
                self.verdict.append(report.verdict(state.solution))
                try:
                    self.verdict.append(src.validation_scan(state.solution.calibration))
                except DeviceError as exc:
                    self.verdict.append(f"validation scan failed: {exc}")
        elif symbol == key.C:
            self.measure_colour()
        elif symbol == key.S:
            if state.solution is not None and state.solution.passed:
                cal = state.solution.calibration
                if self.response is not None:
                    cal.color_mixing = self.response.color_mixing
                    cal.extra.update(self.response.as_extra())
                    if self.src.camera_gamma is not None:
                        cal.extra["camera_gamma"] = self.src.camera_gamma
                cal.save(self.out)
                self.verdict.append(f"wrote {self.out}")
            else:
                self.verdict.append("not saved: the solve has not passed its checks yet")
        elif symbol in self.moves:
            src.move(*self.moves[symbol])  # type: ignore[attr-defined]
        else:
            return
        self.refresh()

    def capture_pose(self) -> None:
        """Film the Gray code on the board as it is; a take that kept being refused saves nothing."""
        try:
            take = self.src.capture()
        except DeviceError as exc:  # PoseNotCapturedError, or a device that failed: said, nothing saved
            self.state.say(f"pose not captured: {exc} (hold the board still and press space again)")
            return
        self.state.add_pose(
            take.frames, self.src.meta, decode_projector_maps, take.timestamps_ns, take.frame_ids, take.note()
        )

    def measure_colour(self) -> None:
        """Flat levels per channel: response curves, colour mixing, saturation / darkness warnings."""
        import shutil

        from calibration.capture import RESPONSE_DIR

        try:
            levels = self.src.levels()
        except DeviceError as exc:
            self.verdict.append(f"colour levels not captured: {exc}")
            return
        gamma = self.src.camera_gamma
        try:
            self.response = measure_response(levels, camera_gamma=gamma if gamma is not None else 1.0)
        except ValueError as exc:
            self.verdict.append(f"colour response: {exc}")
            return
        writer = self.state.writer
        if writer is not None:
            shutil.rmtree(writer.folder / RESPONSE_DIR, ignore_errors=True)  # the latest measurement wins
            writer.write_response(levels, camera_gamma=gamma)
        self.verdict.extend(report.response_text(self.response).splitlines())

    def on_draw(self) -> None:
        self.win.switch_to()  # a projector window of the same process may hold the GL context
        self.win.clear()
        self.panes[0].blit(0, 0)
        self.panes[1].blit(PANE[0], 0)
        self.label.draw()

    def on_key_press(self, symbol: int, modifiers: int) -> bool:
        if symbol in (self.key.ESCAPE, self.key.Q):
            self.quit = True
        else:
            self.handle_key(symbol)
        return True

    def on_close(self) -> None:
        self.quit = True

    def close(self) -> None:
        self.win.close()

    def run(self) -> None:
        """The window's own loop, not pyglet.app.run: that would also redraw and flip a projector
        window of the same process (with nothing drawn) between the patterns it shows."""
        import time

        try:
            while not self.quit:
                self.win.dispatch_events()
                self.src.pump()
                self.poll()
                self.on_draw()
                self.win.flip()
                time.sleep(POLL_S)
        except KeyboardInterrupt:
            pass
        finally:
            self.close()


def is_virtual_rig(cfg) -> bool:
    """The virtual rig with its keyboard-moved board: every device `driver: sim` and nothing else.

    Any other rig, including `sim` devices with options of their own, is opened through the driver
    registries (calibration/rig_source.py) like real hardware.
    """
    rig = cfg.section("rig")
    for kind in ("camera", "projector", "trigger"):
        sec = rig.get(kind)
        if sec is None and kind == "trigger":
            continue
        if not (isinstance(sec, dict) and sec == {"driver": "sim"}):
            return False
    return True


def rig_board_file(cfg, board: str | None) -> Path:
    """The printed board's description: --board, else the config's key `board` (relative to the config)."""
    if board:
        return Path(board)
    name = cfg.get("board", None, types=str)
    if name is None:
        raise InputError(
            f"{cfg.path}: a rig needs the printed board's description: --board board.yaml "
            "(type, rows, cols, square_mm; see README) or key 'board' in the config"
        )
    return (cfg.path.parent / str(name)).resolve()


def run_wizard(args: argparse.Namespace) -> int:
    from app.config import load_config
    from calibration.board import load_board

    cfg = load_config(args.config)
    virtual = is_virtual_rig(cfg)
    board = None if virtual else load_board(rig_board_file(cfg, getattr(args, "board", None)))
    from drivers.projector.screens import display_name

    display_name()  # no display: one clear line before minutes of rig set-up
    out = Path(args.out)
    capture_dir = Path(args.capture) if args.capture else out.with_name(out.stem + ".capture")
    if capture_dir.exists() and (not capture_dir.is_dir() or any(capture_dir.iterdir())):
        raise InputError(f"{capture_dir}: already exists; a capture is never overwritten (choose --capture DIR)")
    if virtual:
        src: BoardSource = SimBoardSource(args.scene, args.seed)
    else:
        from calibration.rig_source import RigBoardSource

        src = RigBoardSource(cfg, board, camera_gamma=args.camera_gamma)  # type: ignore[arg-type]
    try:
        window = WizardWindow(src, out, capture_dir)
        window.run()
    finally:
        src.close()
    n = len(window.state.poses)
    print(f"capture saved in {capture_dir} ({n} poses); slscan calibrate --from {capture_dir} repeats the solve")
    return 0
