"""The operator view: camera image, stripe pseudo-colour and colourised depth, a status line, keys.

pyglet is imported only when the window opens (`run_view`), so headless runs and tests never need
a display. The window runs on the main thread and redraws at up to 60 Hz from the pipeline's
newest result (older ones are counted as stale by the pipeline, never queued here).

Keys: space = snapshot (depth TIFF + PLY + PNGs into snapshot-NNN/), r = start/stop recording a
dump (rec-YYYYmmdd-HHMMSS/), m = switch scheme (two-shot -> one-shot -> graycode), q / Esc = quit;
closing the window quits too. A device fault ends the session with its message on the terminal.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from app import export
from app.decode.stripemap import StripeMap

if TYPE_CHECKING:
    from app.commands.live import Session

SCHEME_CYCLE = ("two-shot", "one-shot", "graycode")


# ------------------------------------------------------------------------------------ pure images


def stripe_colours(stripes: StripeMap) -> np.ndarray:
    """Pseudo-colour of stripe identities (paper Fig. 8b), as `slscan decode` writes it; black = none."""
    return export.stripe_colours(stripes.stripe, stripes.period)


def colourise_depth(depth: np.ndarray, depth_range_mm: tuple[float, float] | None = None) -> np.ndarray:
    """Depth (mm, 0 = none) as RGB over the working range, as `slscan decode` previews it; black = none."""
    return export.depth_preview(depth, depth_range_mm)


def to_display(image: np.ndarray) -> np.ndarray:
    """Any camera image (uint8/uint16, RGB) as uint8 RGB."""
    if image.dtype == np.uint16:
        return (image >> 8).astype(np.uint8)
    return image


# ------------------------------------------------------------------------------------ window


class LiveView:
    """A pyglet window showing the newest result of a running LivePipeline."""

    def __init__(self, session: Session, args: argparse.Namespace) -> None:
        from app.pipeline import LivePipeline

        self.session = session
        self.args = args
        self.LivePipeline = LivePipeline
        self.recorder: Any = None
        self.record_msgs: list[str] = []
        self.snapshots = 0
        self.message = ""
        self.processor = session.processor()
        self.pipe: Any = None  # started once the window is open (no devices running behind a failed window)
        self.cam_size = session.calibration.camera_size

    def _start_pipeline(self):
        pipe = self.LivePipeline(
            lambda: self.session.make_loop(timeout_s=self.args.timeout),
            self.processor,
            workers=self.args.workers,
            max_frames=self.args.frames,
            recorder=self.recorder,
        )
        pipe.start()
        return pipe

    # -- keys ------------------------------------------------------------------------------
    def snapshot(self) -> None:
        from app.commands.live import save_result

        res = self.pipe.latest
        if res is None:
            self.message = "snapshot: no depth map yet"
            return
        while Path(f"snapshot-{self.snapshots:03d}").exists():
            self.snapshots += 1
        out = save_result(res, self.processor, f"snapshot-{self.snapshots:03d}")
        self.message = f"snapshot written to {out}"

    def toggle_recording(self) -> None:
        from app.commands.live import open_recorder

        if self.recorder is None:
            folder = Path(time.strftime("rec-%Y%m%d-%H%M%S"))
            self.recorder = open_recorder(self.session, folder, self.args.png_level)
            self.pipe.set_recorder(self.recorder)
            self.message = f"recording to {folder}"
        else:
            rec = self.pipe.set_recorder(None)
            rec.close()
            self.message = rec.summary()
            self.record_msgs.append(self.message)
            self.recorder = None

    def switch_scheme(self) -> None:
        nxt = SCHEME_CYCLE[(SCHEME_CYCLE.index(self.session.scheme) + 1) % len(SCHEME_CYCLE)]
        if self.recorder is not None:
            self.toggle_recording()  # a dump holds one scheme
        self.pipe.stop()
        self.pipe.join()
        try:
            session = self.session.with_scheme(nxt)
            processor = session.processor()
        except Exception as exc:
            self.message = f"cannot switch to {nxt}: {exc}"
            self.pipe = self._start_pipeline()
            return
        self.session, self.processor = session, processor
        self.pipe = self._start_pipeline()
        self.message = f"scheme: {nxt}"

    def close(self) -> None:
        self.pipe.stop()
        self.pipe.join()
        if self.recorder is not None:
            rec = self.pipe.set_recorder(None) or self.recorder
            rec.close()
            self.record_msgs.append(rec.summary())
            self.recorder = None

    # -- drawing ---------------------------------------------------------------------------
    def run(self) -> int:
        from drivers.projector.screens import import_pyglet, open_display

        pyglet = import_pyglet()
        from pyglet.window import key

        # Three panes side by side, scaled down (never up) to fit the operator's screen.
        w, h = self.cam_size
        screen = open_display().get_default_screen()
        scale = min(1.0, (screen.width - 16) / (3 * w), (screen.height - 100) / h)
        pw, ph = int(w * scale), int(h * scale)
        win = pyglet.window.Window(3 * pw, ph + 28, caption="slscan live", vsync=False)
        blank = np.zeros((self.cam_size[1], self.cam_size[0], 3), np.uint8)
        images = [pyglet.image.ImageData(blank.shape[1], blank.shape[0], "RGB", blank.tobytes()) for _ in range(3)]
        label = pyglet.text.Label("", x=6, y=8, font_size=11, color=(255, 255, 255, 255))
        titles = [
            pyglet.text.Label(t, x=i * pw + 6, y=ph + 28 - 18, font_size=10, color=(255, 255, 0, 255))
            for i, t in enumerate(("camera", "stripes", "depth"))
        ]

        self.pipe = self._start_pipeline()

        def upload(i: int, rgb: np.ndarray) -> None:
            rgb = np.ascontiguousarray(to_display(rgb))
            images[i].set_data("RGB", -rgb.shape[1] * 3, rgb.tobytes())  # negative pitch: row 0 on top

        @win.event
        def on_draw() -> None:
            win.clear()
            for i, img in enumerate(images):
                img.blit(i * pw, 28, width=pw, height=ph)
            for t in titles:
                t.draw()
            label.draw()

        @win.event
        def on_key_press(symbol: int, modifiers: int) -> bool:
            if symbol in (key.ESCAPE, key.Q):
                pyglet.app.exit()
            elif symbol == key.SPACE:
                self.snapshot()
            elif symbol == key.R:
                self.toggle_recording()
            elif symbol == key.M:
                self.switch_scheme()
            return True

        @win.event
        def on_close() -> None:
            pyglet.app.exit()

        def tick(dt: float) -> None:
            res = self.pipe.take_latest()
            if res is not None:
                upload(0, res.image)
                upload(1, stripe_colours(res.stripes))
                upload(2, colourise_depth(res.depth, self.processor.triangulator.depth_range_mm))
            elif self.pipe.latest_frame is not None and self.pipe.latest is None:
                upload(0, self.pipe.latest_frame.image)
            rec = f"REC {self.recorder.stats.written}" if self.recorder is not None else ""
            if self.recorder is not None and self.recorder.message:
                rec = self.recorder.message
            from app.pipeline import status_line

            label.text = (
                f"[{self.session.scheme}] "
                + status_line(self.pipe.figures(), rec)
                + (f"  | {self.message}" if self.message else "")
            )
            if not self.pipe.running:
                pyglet.app.exit()

        pyglet.clock.schedule_interval(tick, 1 / 60)
        try:
            pyglet.app.run()
        except KeyboardInterrupt:
            pass
        finally:
            pyglet.clock.unschedule(tick)
            win.close()
            self.close()
        for msg in self.record_msgs:
            print(msg)
        if self.pipe.error:
            print(f"slscan live: stopped: {self.pipe.error}")
            return 2
        if self.pipe.stop_reason:
            print(f"slscan live: stopped cleanly: {self.pipe.stop_reason}")
        return 0


def run_view(session: Session, args: argparse.Namespace) -> int:
    """Open the operator window over a live pipeline; returns the exit status."""
    return LiveView(session, args).run()
