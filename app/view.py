"""The operator view: camera image, stripe pseudo-colour, colourised depth and a 3D point view, a status line, keys.

pyglet is imported only when the window opens (`run_view`), so headless runs and tests never need
a display. Four panels, 2 x 2: camera | stripes / depth | 3D points. The window redraws at up to
30 Hz from the pipeline's newest result (older ones are counted as stale by the pipeline, never
queued here), the status line 5 times a second: on a 2-core machine every millisecond the view
spends is taken from the decoder (`slscan bench --live` prints the view's image work).

The 3D point view (app/pointview.py, software-rendered in numpy) shows every 4th pixel each way
(640x480: at most 19,200 points) of the newest depth map, coloured by depth like the depth panel.
It **orbits slowly by itself** (yaw +-30 degrees, 8 s period) until an **arrow key** turns it
(left/right = yaw, up/down = pitch, 10 degrees a press); Home returns to the camera's view and
the orbit; c switches the point colours between depth and camera.

Keys: space = snapshot (depth TIFF + PNG16 + PLY + PNGs + scan.yaml into snapshot-NNN/, coloured by a texture frame
taken for it), t = take a white-light texture frame now, r = start/stop recording a
dump (rec-YYYYmmdd-HHMMSS/), m = switch scheme (two-shot -> one-shot -> graycode), f = start/stop fusion (a new
model each start), s = save the model (model-NNN/: model.ply, model.obj, model.trajectory.csv, as `slscan fuse`
writes them), q / Esc = quit; closing the window quits too. A device fault ends the session with its message on the
terminal.

Fusion (app/fusion/live.py, needs slscan[fusion]): the decode workers offer every result to the fusion thread's
one-slot mailbox and never wait for it, so capture and decoding go on at their pace whatever fusion costs. While
fusion runs the 3D panel shows the model (the registration's map of model points, drawn as the scan's points are,
coloured by depth in the model's frame, which is the camera's at the first fused scan) and the status line its state:
tracking / LOST (n scans in a row failed registration), scans fused, dropped, late (replaced in the mailbox), skipped
(tracked, not integrated). A save copies the model between two scans and writes it on a thread of its own.

Threads: pyglet wants all windows of a process on one thread. The view's loop runs on the main
thread and owns the projector window too when the rig has one (`PygletProjector`): the devices
are opened here, and the capture loop's projector calls are handed to this thread
(app/owner_thread.py), served between redraws. A redraw runs in two phases (images: conversions
and texture uploads; draw: blits and flip), each right after a served flip or when its recent
cost fits before the next show is due (RedrawPlanner), so the view delays the projector as little
as it can. Esc, q or closing the projector window ends the session cleanly, as in the view.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from app import export
from app.decode.mosaic import to_rgb
from app.decode.stripemap import StripeMap
from app.live_pipeline import status_line
from app.pointview import _TURBO, PointView, decimate, decimated_rays, depth_colours, render_points

if TYPE_CHECKING:
    from app.live_pipeline import LiveResult
    from app.owner_thread import OwnerThreadProjector
    from app.session import Session

SCHEME_CYCLE = ("two-shot", "one-shot", "graycode")
REDRAW_S = 1 / 30  # measured at 640x480 on Xvfb: a redraw (4 blits + flip) costs ~6 ms of the main thread
STATUS_S = 0.2  # the status line's text layout costs ~1 ms: 5 times a second is plenty to read
POINT_BUDGET = 20_000  # points drawn at most: the decimation step follows from the camera size
TURN_DEG = 10.0


# ------------------------------------------------------------------------------------ pure images


# A snapshot waits at most this long for the texture frame it asked for (then saves without it, and says so).
SNAPSHOT_TEXTURE_WAIT_S = 1.0


def stripe_colours(stripes: StripeMap) -> np.ndarray:
    """Pseudo-colour of stripe identities (paper Fig. 8b), as `slscan decode` writes it; black = none."""
    return export.stripe_colours(stripes.stripe, stripes.period)


def colourise_depth(depth: np.ndarray, depth_range_mm: tuple[float, float] | None = None) -> np.ndarray:
    """Depth (mm, 0 = none) as RGB over the working range, as `slscan decode` previews it; black = none."""
    return export.depth_preview(depth, depth_range_mm)


# The view's stripe colours: export.stripe_colours of every stripe number, looked up per pixel.
_STRIPE_TABLE = export.stripe_colours(np.arange(-1, 1 << 14, dtype=np.int64).reshape(1, -1))[0]  # [0] = none


def stripe_panel(stripes: StripeMap) -> np.ndarray:
    """stripe_colours(stripes), pixel for pixel, in a fraction of its time (one table lookup per pixel)."""
    s = np.floor((stripes.column + 0.5) / stripes.stripe_width)
    np.fmax(s, -1, out=s)  # NaN (no value) -> -1
    np.minimum(s, len(_STRIPE_TABLE) - 2, out=s)
    s += 1
    return np.take(_STRIPE_TABLE, s.astype(np.intp), axis=0)  # np.take: ~4x faster than fancy indexing here


_TURBO_NONE = np.concatenate([_TURBO, np.zeros((1, 3), np.uint8)])  # index 256 = no depth (black)


def depth_panel(depth: np.ndarray, depth_range_mm: tuple[float, float] | None = None) -> np.ndarray:
    """colourise_depth(depth, range), pixel for pixel: the same float32 steps in place, then one table lookup."""
    m = depth > 0
    if depth_range_mm is None:
        lo, hi = (float(depth[m].min()), float(depth[m].max())) if m.any() else (0.0, 1.0)
    else:
        lo, hi = depth_range_mm
    t = depth - np.float32(lo)
    t /= np.float32(max(hi - lo, 1e-6))
    np.clip(t, 0, 1, out=t)
    np.subtract(1, t, out=t)
    t *= 255
    g = t.astype(np.uint8).astype(np.uint16)
    g[~m] = 256  # the table's black entry: no value
    return np.take(_TURBO_NONE, g, axis=0)


def to_display(image: np.ndarray, mosaic: str | None = None) -> np.ndarray:
    """Any camera image (uint8/uint16, RGB, or a raw Bayer frame with its mosaic) as uint8 RGB."""
    image = to_rgb(image, mosaic)
    if image.dtype == np.uint16:
        return (image >> 8).astype(np.uint8)
    return image


def panel_size(camera_size: tuple[int, int], screen_size: tuple[int, int]) -> tuple[int, int]:
    """One panel of the 2 x 2 grid: the camera size, scaled down (never up) to fit the screen."""
    w, h = camera_size
    scale = min(1.0, (screen_size[0] - 16) / (2 * w), (screen_size[1] - 100) / (2 * h))
    return max(1, int(w * scale)), max(1, int(h * scale))


class RedrawPlanner:
    """When the view may use the main thread without delaying the projector's next show.

    With a projector window, the main thread also runs the shows: one per refresh, queued about a
    period after the last one. A redraw is split in two phases ("images": conversions and uploads;
    "draw": blits and flip) and a phase runs only when its recent cost fits before the next show
    is due. A phase that never fits still runs every `starve_s`, so the view never freezes.
    """

    PHASES = ("images", "draw")

    def __init__(self, period_s: float, margin_s: float = 0.0015, starve_s: float = 0.5) -> None:
        self.period_s, self.margin_s, self.starve_s = period_s, margin_s, starve_s
        self.cost_s = dict.fromkeys(self.PHASES, 0.004)  # running estimate per phase
        self.phase = "images"
        self.waiting_since: float | None = None

    def may_run(self, now: float, last_request: float | None, flipped: bool = False) -> bool:
        """flipped: a show was served just now, the most room there will be before the next one."""
        if self.waiting_since is None:
            self.waiting_since = now
        if last_request is None or flipped or now - self.waiting_since >= self.starve_s:
            return True
        slack = last_request + self.period_s - now - self.margin_s
        return self.cost_s[self.phase] <= slack

    def ran(self, seconds: float) -> str:
        """Record the phase's cost; returns the phase that ran and moves on to the next."""
        done = self.phase
        self.cost_s[done] = 0.7 * self.cost_s[done] + 0.3 * seconds
        self.phase = self.PHASES[(self.PHASES.index(done) + 1) % len(self.PHASES)]
        self.waiting_since = None
        return done


class PointPanel:
    """The 3D point view of a result: decimated points, a slowly orbiting or key-turned pose."""

    def __init__(self, ray: np.ndarray, camera_matrix: np.ndarray, depth_range_mm: tuple[float, float]) -> None:
        h, w = ray.shape[:2]
        self.step = max(1, int(np.ceil(np.sqrt(w * h / POINT_BUDGET))))
        self.rays = decimated_rays(ray, self.step)
        self.depth_range_mm = depth_range_mm
        size = (self.rays.shape[2], self.rays.shape[1])
        self.home = PointView.for_camera(camera_matrix, (w, h), size, 0.5 * (depth_range_mm[0] + depth_range_mm[1]))
        self.view = self.home
        self.manual = False  # an arrow key took over from the orbit
        self.camera_colours = False
        self.t0 = time.monotonic()

    @property
    def size(self) -> tuple[int, int]:
        return self.home.size

    def turn(self, d_yaw: float, d_pitch: float) -> None:
        if not self.manual:
            self.view = self.home.orbit(time.monotonic() - self.t0)  # start from what is on screen
        self.view = self.view.turned(d_yaw, d_pitch)
        self.manual = True

    def reset(self) -> None:
        self.view, self.manual, self.t0 = self.home, False, time.monotonic()

    def pose(self) -> PointView:
        return self.view if self.manual else self.home.orbit(time.monotonic() - self.t0)

    def render_model(self, points: np.ndarray) -> np.ndarray:
        """The fused model's points (model frame = the camera's at its first scan), at most POINT_BUDGET of them,
        coloured by depth in that frame, from the panel's pose."""
        step = max(1, -(-len(points) // POINT_BUDGET))
        xyz = np.asarray(points[::step], np.float32)
        return render_points(xyz, depth_colours(xyz, self.depth_range_mm), self.pose())

    def render(self, result: LiveResult) -> np.ndarray:
        xyz, _ = decimate(result.depth, self.rays, None, self.step)
        if self.camera_colours:
            # The brightest of the set's frames: two-shot lights each channel in one of its two frames.
            frames = [to_display(f.image, f.mosaic)[:: self.step, :: self.step] for f in result.frameset.frames]
            rgb = np.maximum.reduce(frames)[result.depth[:: self.step, :: self.step] > 0]
        else:
            rgb = depth_colours(xyz, self.depth_range_mm)
        return render_points(xyz, rgb, self.pose())


# ------------------------------------------------------------------------------------ window


# ------------------------------------------------------------------------------------ window


class LiveView:
    """A pyglet window showing the newest result of a running LivePipeline (see the module docstring)."""

    def __init__(self, session: Session, args: argparse.Namespace) -> None:
        from app.live_pipeline import LivePipeline

        self.session = session
        self.args = args
        self.LivePipeline = LivePipeline
        self.recorder: Any = None
        self.record_msgs: list[str] = []
        self.snapshots = 0
        self._snapshot_after: tuple[float, int | None] | None = None  # (deadline, texture frame id before) pending
        self.message = ""
        self.show_now: Any = None  # shows a status text at once (set while the window is open)
        self.status_text = ""  # what the status line shows
        self.processor = session.processor()
        self.pipe: Any = None  # started once the window is open (no devices running behind a failed window)
        self.projector: OwnerThreadProjector | None = None  # the rig's projector window, served by this thread
        self.cam_size = session.calibration.camera_size
        self.points = self._point_panel()
        self.win: Any = None
        self.quit = False
        self.redraw_ms: list[float] = []  # time of each redraw's image work (tests and the bench read it)
        self.points_ms: list[float] = []
        self.main_cpu_s = 0.0  # CPU the view's loop used (redraws, and projector calls it served)
        self.fusion: Any = None  # LiveFusion while fusing, and after a stop until the next start (for s)
        self.models = 0  # model-NNN folders written
        self._saver: Any = None  # the thread writing a model

    def _point_panel(self) -> PointPanel:
        tri = self.processor.triangulator
        return PointPanel(tri.ray, self.session.calibration.camera_matrix, tri.depth_range_mm)

    def _start_pipeline(self):
        from app.owner_thread import HandOver
        from app.publisher import result_sink

        # A window that belongs to this thread (pyglet) is served from the view's loop.
        hand_over = HandOver()
        loop = self.session.make_loop(wrap_projector=hand_over, timeout_s=self.args.timeout)
        self.projector = hand_over.proxy
        pipe = self.LivePipeline(
            lambda: loop,
            self.processor,
            workers=self.args.workers,
            max_frames=self.args.frames,
            recorder=self.recorder,
            on_result=self._sink(result_sink(self.args, self.processor)),  # --publish (app/publisher.py)
        )
        pipe.start()
        return pipe

    def _stop_pipeline(self) -> None:
        """Stop the session, serving the projector window until the capture loop has closed it."""
        self.pipe.stop()
        while self.pipe.running:
            if self.projector is not None:
                self.projector.serve(0.01)
            else:
                time.sleep(0.01)
        self.pipe.join()
        if self.projector is not None:
            self.projector.shutdown()
            self.projector.projector.close()  # already closed by the loop, unless it failed first
            self.projector = None

    def _sink(self, publish: Any) -> Any:
        """The workers' on_result: --publish, then the fusion thread's mailbox while fusion runs (never waits)."""

        def sink(res: Any) -> None:
            if publish is not None:
                publish(res)
            fusion = self.fusion
            if fusion is not None and fusion.running:
                fusion.offer(res)

        return sink

    # -- keys ------------------------------------------------------------------------------
    def toggle_fusion(self) -> None:
        """f: start fusing into a new model, or stop (the model is kept for s)."""
        if self.fusion is not None and self.fusion.running:
            self.fusion.stop()
            self.message = self.fusion.summary()
            return
        if self._saver is not None and self._saver.is_alive():
            self.message = "fusion: a model is still being written"
            return
        from app.fusion.live import LiveFusion

        voxel = float(getattr(self.args, "voxel_mm", 0.5))
        try:
            volume = fusion_volume(self.session, getattr(self.args, "volume_mm", None))
            rng = self.session.depth_range_mm or (100.0, 5000.0)
            self.fusion = LiveFusion(self.session.calibration, rng, volume, voxel)
        except Exception as exc:  # Open3D missing, a volume too big for memory: one line, the session goes on
            self.message = f"fusion: {exc}"
            return
        self.message = "fusion started"

    def save_model(self) -> None:
        """s: the model's mesh, as `slscan fuse` writes it, into model-NNN/ (written on a thread of its own)."""
        fusion = self.fusion
        if fusion is None or fusion.fuser.stats.integrated == 0:
            self.message = "save: no model yet (f starts fusion)"
            return
        if self._saver is not None and self._saver.is_alive():
            self.message = "save: a model is still being written"
            return
        while Path(f"model-{self.models:03d}").exists():
            self.models += 1
        out = Path(f"model-{self.models:03d}") / "model.ply"
        self.message = f"saving the model ({fusion.fuser.stats.integrated} scans) to {out.parent}"

        def write() -> None:
            try:
                ply, obj, csv, n = fusion.save(out)
                self.message = f"model ({n} scans) written to {ply}, {obj}, {csv}"
            except Exception as exc:  # no surface yet, a full disk: said on the status line
                self.message = f"save: {exc}"

        import threading

        self._saver = threading.Thread(target=write, name="model-save", daemon=True)
        self._saver.start()

    def snapshot(self) -> None:
        """Ask for a texture frame, then save the first result it colours (poll_snapshot), or the newest one after
        SNAPSHOT_TEXTURE_WAIT_S without it."""
        res = self.pipe.latest
        if res is None:
            self.message = "snapshot: no depth map yet"
            return
        if self.pipe.request_texture():
            before = self.pipe.latest_texture.frame_id if self.pipe.latest_texture is not None else None
            self._snapshot_after = (time.monotonic() + SNAPSHOT_TEXTURE_WAIT_S, before)
            self.message = "snapshot: taking a texture frame"
            return
        self._save_snapshot(res)

    def poll_snapshot(self) -> None:
        """Save the pending snapshot once a result coloured by a newer texture frame is in (or at its deadline)."""
        if self._snapshot_after is None:
            return
        deadline, before = self._snapshot_after
        res = self.pipe.latest
        fresh = res is not None and res.texture is not None and res.texture.frame_id != before
        if fresh or time.monotonic() >= deadline:
            self._snapshot_after = None
            if res is not None:
                self._save_snapshot(res)

    def request_texture(self) -> None:
        self.message = "texture frame requested" if self.pipe.request_texture() else "texture: the loop is not running"

    def _save_snapshot(self, res: Any) -> None:
        from app.session import save_result

        while Path(f"snapshot-{self.snapshots:03d}").exists():
            self.snapshots += 1
        out = save_result(res, self.processor, f"snapshot-{self.snapshots:03d}", self.session.calibration_source)
        self.message = f"snapshot written to {out}" + ("" if res.texture is not None else " (no texture frame)")

    def toggle_recording(self) -> None:
        from app.session import open_recorder

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
        self._stop_pipeline()
        try:
            session = self.session.with_scheme(nxt)
            if self.show_now is not None:  # (the window waits while the new decoder is compiled or loaded)
                self.show_now(f"switching to {nxt}: preparing its decoder (compiling it on a first run takes a minute)")
            processor = session.processor()
        except Exception as exc:
            self.message = f"cannot switch to {nxt}: {exc}"
            self.pipe = self._start_pipeline()
            return
        self.session, self.processor = session, processor
        self.points = self._point_panel()
        self.pipe = self._start_pipeline()
        self.message = f"scheme: {nxt}"

    def close(self) -> None:
        self._stop_pipeline()
        if self._saver is not None:
            self._saver.join()
        if self.fusion is not None and self.fusion.running:
            self.fusion.stop()
        if self.recorder is not None:
            rec = self.pipe.set_recorder(None) or self.recorder
            rec.close()
            self.record_msgs.append(rec.summary())
            self.recorder = None

    def on_key(self, symbol: int, key: Any) -> None:
        if symbol in (key.ESCAPE, key.Q):
            self.quit = True
        elif symbol == key.SPACE:
            self.snapshot()
        elif symbol == key.R:
            self.toggle_recording()
        elif symbol == key.T:
            self.request_texture()
        elif symbol == key.M:
            self.switch_scheme()
        elif symbol == key.F:
            self.toggle_fusion()
        elif symbol == key.S:
            self.save_model()
        elif symbol == key.C:
            self.points.camera_colours = not self.points.camera_colours
        elif symbol == key.HOME:
            self.points.reset()
        else:
            turn = {key.LEFT: (-TURN_DEG, 0), key.RIGHT: (TURN_DEG, 0), key.UP: (0, TURN_DEG), key.DOWN: (0, -TURN_DEG)}
            if symbol in turn:
                self.points.turn(*turn[symbol])

    # -- drawing ---------------------------------------------------------------------------
    def run(self) -> int:
        from drivers.projector.screens import import_pyglet, open_display

        pyglet = import_pyglet()
        from pyglet import gl
        from pyglet.window import key

        screen = open_display().get_default_screen()
        pw, ph = panel_size(self.cam_size, (screen.width, screen.height))
        status_h = 62  # three lines: the status line (which wraps on a narrow window) and fusion's
        self.win = win = pyglet.window.Window(2 * pw, 2 * ph + status_h, caption="slscan live", vsync=False)
        self.panel_rects = [(0, 0, pw, ph), (pw, 0, pw, ph), (0, ph, pw, ph), (pw, ph, pw, ph)]  # x, y from the top
        # One texture per panel, made once and updated in place (glTexSubImage2D): ImageData.blit
        # would make a new texture after every set_data.
        textures: list[Any] = []
        for i, (w, h) in enumerate([self.cam_size] * 3 + [self.points.size]):
            tex = pyglet.image.Texture.create(w, h)
            gl.glBindTexture(tex.target, tex.id)
            if i == 3:  # points stay crisp squares when the panel scales them up
                gl.glTexParameteri(tex.target, gl.GL_TEXTURE_MAG_FILTER, gl.GL_NEAREST)
                gl.glTexParameteri(tex.target, gl.GL_TEXTURE_MIN_FILTER, gl.GL_NEAREST)
            tex.blit_into(pyglet.image.ImageData(w, h, "RGB", bytes(w * h * 3)), 0, 0, 0)
            textures.append(tex)
        label = pyglet.text.Label(
            "", x=6, y=status_h - 4, width=2 * pw - 12, multiline=True, anchor_y="top", font_size=10
        )
        titles = [
            pyglet.text.Label(t, x=x + 6, y=2 * ph + status_h - y - 18, font_size=10, color=(255, 255, 0, 255))
            for t, (x, y, _, _) in zip(("camera", "stripes", "depth", "3D points"), self.panel_rects, strict=True)
        ]
        self.panel_titles = titles

        def upload(i: int, rgb: np.ndarray) -> None:
            rgb = np.ascontiguousarray(to_display(rgb))
            h, w = rgb.shape[:2]
            data = pyglet.image.ImageData(w, h, "RGB", rgb.tobytes(), pitch=-w * 3)  # negative pitch: row 0 on top
            textures[i].blit_into(data, 0, 0, 0)

        def draw() -> None:
            win.switch_to()
            win.clear()
            for tex, (x, y, w, h) in zip(textures, self.panel_rects, strict=True):
                tex.blit(x, 2 * ph + status_h - y - h, width=w, height=h)
            for t in titles:
                t.draw()
            label.draw()
            win.flip()

        @win.event
        def on_key_press(symbol: int, modifiers: int) -> bool:
            self.on_key(symbol, key)
            return True

        @win.event
        def on_close() -> bool:
            self.quit = True
            return True  # closed below, after the session stopped

        last: LiveResult | None = None
        status_due: list[Any] = [0.0, None]  # when the status line is next laid out, and its message

        def show_now(text: str) -> None:
            label.text = self.status_text = f"[{self.session.scheme}] {text}"
            draw()
            status_due[0] = 0.0  # the usual status line again at the next redraw

        self.show_now = show_now

        def tick() -> None:
            nonlocal last
            t0 = time.perf_counter()
            win.switch_to()  # the projector window's show may have made its own GL context current
            self.poll_snapshot()
            res = self.pipe.take_latest()
            if res is not None:
                last = res
                upload(0, res.image)
                upload(1, stripe_panel(res.stripes))
                upload(2, depth_panel(res.depth, self.processor.triangulator.depth_range_mm))
            elif self.pipe.latest_frame is not None and self.pipe.latest is None:
                frame = self.pipe.latest_frame
                upload(0, to_display(frame.image, frame.mosaic))
            fusing = self.fusion is not None and self.fusion.running
            if fusing:
                t1 = time.perf_counter()
                upload(3, self.points.render_model(self.fusion.fuser.tracker.map.points))
                self.points_ms.append((time.perf_counter() - t1) * 1e3)
            elif last is not None:
                t1 = time.perf_counter()
                upload(3, self.points.render(last))
                self.points_ms.append((time.perf_counter() - t1) * 1e3)
            if time.monotonic() >= status_due[0] or self.message != status_due[1]:
                status_due[:] = [time.monotonic() + STATUS_S, self.message]
                rec = f"REC {self.recorder.stats.written}" if self.recorder is not None else ""
                if self.recorder is not None and self.recorder.message:
                    rec = self.recorder.message
                label.text = (
                    f"[{self.session.scheme}] "
                    + status_line(self.pipe.figures(), rec)
                    + (f"  | {self.message}" if self.message else "")
                    + (f"\n{self.fusion.state()}" if self.fusion is not None else "")
                )
                self.status_text = label.text
                title = f"model ({len(self.fusion.fuser.tracker.map)} points)" if fusing else "3D points"
                if titles[3].text != title:
                    titles[3].text = title
            self.redraw_ms.append((time.perf_counter() - t0) * 1e3)
            del self.redraw_ms[:-1000], self.points_ms[:-1000]

        try:
            self.pipe = self._start_pipeline()
        except BaseException:
            win.close()  # the devices did not open: their error is the message
            raise
        next_draw = time.monotonic()
        cpu0 = time.thread_time()
        planner = RedrawPlanner(1.0 / self.session.rate_hz)
        try:
            # The view's own loop (not pyglet.app.run, which would redraw and flip the projector
            # window too): projector calls, window events, then a redraw in two phases, each only
            # when it fits before the projector's next show (RedrawPlanner).
            while not self.quit:
                flipped = False
                if self.projector is not None:
                    flipped = self.projector.serve(0.005) > 0
                else:
                    time.sleep(min(0.005, max(0.0, next_draw - time.monotonic())))
                win.dispatch_events()
                pyglet.clock.tick()  # functions scheduled on pyglet's clock (tests drive the view with them)
                if self.quit or not self.pipe.running:
                    break
                now = time.monotonic()
                if planner.phase == "images" and now < next_draw:
                    continue
                last_request = self.projector.last_request_s if self.projector is not None else None
                if not planner.may_run(now, last_request, flipped):
                    continue
                t0 = time.perf_counter()
                if planner.phase == "images":
                    next_draw = max(next_draw + REDRAW_S, now - REDRAW_S)
                    tick()
                else:
                    draw()
                planner.ran(time.perf_counter() - t0)
        except KeyboardInterrupt:
            pass
        finally:
            self.main_cpu_s = time.thread_time() - cpu0
            try:
                self.close()
            finally:
                win.close()
        for msg in self.record_msgs:
            print(msg)
        if self.pipe.error:
            print(f"slscan live: stopped: {self.pipe.error}")
            return 2
        if self.pipe.stop_reason:
            print(f"slscan live: stopped cleanly: {self.pipe.stop_reason}")
        return 0


def fusion_volume(session: Session, volume_arg: str | None) -> tuple[float, ...] | None:
    """The working volume fusion keeps of each scan: --volume-mm, else the session's (the virtual rig scene's or a
    replayed dump's), else None (all of each scan)."""
    from app.argtypes import volume_mm

    if volume_arg is not None:
        return volume_mm(volume_arg)
    return session.working_volume_mm


def run_view(session: Session, args: argparse.Namespace) -> int:
    """Open the operator window over a live pipeline; returns the exit status."""
    return LiveView(session, args).run()
