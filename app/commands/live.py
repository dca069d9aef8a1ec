"""`slscan live`: the live scanning session (operator view, or --headless).

The session itself (building it from a config, recording, saving a result) is `app.session`.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from app.argtypes import positive_float, positive_int
from app.live_pipeline import DECODE_WORKERS, WORKERS_HELP, LivePipeline, status_line
from app.owner_thread import HandOver
from app.publisher import add_publish_arguments, open_publisher, result_sink
from app.session import Session, build_session, describe, open_recorder, save_result
from app.termination import exit_status, stopped_by
from core.errors import DeviceError, InputError
from core.patterns import SCHEMES

HELP = "run the live scanning session (virtual rig by default; --config for real hardware)"

EPILOG = """\
examples:
  slscan live                                   # the virtual rig (config/sim.yaml), operator window
  slscan live --headless --frames 600           # same loop, no window: prints the figures, saves the last scan
  slscan live --config rig.yaml                 # real camera, projector and trigger box
  slscan live --headless --frames 300 --record rec/   # and record the checked frames as a dump
  slscan live --publish tcp://127.0.0.1:5556    # and stream every scan's depth (slscan.Subscriber reads it)

keys in the window: space = snapshot (depth TIFF and PNG16, PLY, PNGs, scan.yaml; coloured by a texture frame
taken for it), t = take a white-light texture frame, r = start/stop recording, m = switch scheme, f = start/stop
fusion, s = save the fused model (model-NNN/: PLY, OBJ, trajectory), q / Esc = quit.
Without a display, `slscan live` says so and runs headless.
"""

# ------------------------------------------------------------------------------------ command


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "live", help=HELP, description=HELP, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--config", metavar="FILE", help="rig configuration (default: config/sim.yaml, the virtual rig)")
    p.add_argument("--scheme", choices=SCHEMES, help="pattern scheme (default: the config's scheme.name)")
    p.add_argument("--headless", action="store_true", help="no window: run the loop, print figures, save the last scan")
    p.add_argument("--frames", type=positive_int, metavar="N", help="stop after N camera frames (headless default 300)")
    p.add_argument("--out", metavar="DIR", help="headless: folder for the last scan (default live-YYYYmmdd-HHMMSS)")
    p.add_argument("--record", metavar="DIR", help="record the checked frames as a dump in DIR (must not exist)")
    p.add_argument("--png-level", type=int, default=0, metavar="L", help="PNG level for recordings (0 fastest; 1..9)")
    p.add_argument("--workers", type=positive_int, default=DECODE_WORKERS, help=WORKERS_HELP)
    p.add_argument(
        "--timeout", type=positive_float, default=2.0, metavar="S", help="camera timeout in seconds (default 2)"
    )
    p.add_argument(
        "--texture-every",
        type=positive_int,
        metavar="N",
        help="show a white-light texture frame every N frames, which colours the clouds after it (default: the "
        "config's capture.texture_every; else only on a snapshot or the t key)",
    )
    add_publish_arguments(p)
    add_fusion_arguments(p)
    p.set_defaults(func=run)


def add_fusion_arguments(p: argparse.ArgumentParser) -> None:
    """--fuse, --voxel-mm, --volume-mm: live fusion (slscan live, slscan replay)."""
    p.add_argument(
        "--fuse",
        action="store_true",
        help="headless: register and integrate every scan into a mesh (slscan[fusion]; in the window: the f key)",
    )
    p.add_argument(
        "--voxel-mm",
        type=positive_float,
        default=0.5,
        metavar="V",
        help="fusion (--fuse, f): TSDF voxel size (default 0.5)",
    )
    p.add_argument(
        "--volume-mm",
        metavar="X0,X1,Y0,Y1,Z0,Z1",
        help="fusion (--fuse, f): the working volume, camera mm (default: the virtual rig scene's or the dump's, "
        "else all)",
    )


def run(args: argparse.Namespace) -> int:
    if args.frames is not None and args.frames < 1:
        raise InputError(f"--frames {args.frames}: must be at least 1")
    if not args.headless and not os.environ.get("DISPLAY"):
        # The session itself needs no screen: run it headless rather than refuse (say so on stderr).
        print(
            "slscan live: no display for the operator window (DISPLAY is not set): running --headless", file=sys.stderr
        )
        args.headless = True
    publisher = open_publisher(args)  # bound before the session starts: a bad address is said first
    try:
        session = build_session(args.config, scheme=args.scheme)
        if args.texture_every is not None:
            if args.texture_every < 2:
                raise InputError(f"--texture-every {args.texture_every}: must be at least 2 frames")
            session.texture_every = args.texture_every
        if not args.headless:
            from app.view import run_view

            return run_view(session, args)
        return run_headless(session, args)
    finally:
        if publisher is not None:
            publisher.close()


def run_headless(session: Session, args: argparse.Namespace, label: str = "live") -> int:
    frames = args.frames or 300
    out = Path(args.out) if args.out else Path(time.strftime("live-%Y%m%d-%H%M%S"))
    session.check_outputs(out, getattr(args, "record", None))  # before the decoder compiles and the devices open
    # the decoder first: an error (or Ctrl-C) while it compiles leaves no empty dump behind
    processor = session.processor()
    fusion = _open_fusion(session, args)
    recorder = open_recorder(session, args.record, args.png_level) if getattr(args, "record", None) else None
    # The devices open on this thread: a projector window (pyglet) stays with it, and this thread
    # serves the window's calls while it waits, so the capture loop's projector thread paces the
    # flips by the trigger, never by the camera's grab (app/owner_thread.py).
    hand_over = HandOver()
    try:
        loop = session.make_loop(wrap_projector=hand_over, timeout_s=args.timeout)
    except BaseException:
        if recorder is not None:
            recorder.close()
        raise
    pipe = LivePipeline(
        lambda: loop,
        processor,
        workers=args.workers,
        max_frames=frames,
        recorder=recorder,
        on_result=_both(result_sink(args, processor), None if fusion is None else fusion.offer),
        texture_at_end=True,  # (the saved last scan: coloured by a texture frame taken near the end)
    )
    count = "every frame" if frames >= 10**12 else f"{frames} frames"
    print(f"slscan {label}: {session.scheme} on {describe(session)}, {count}", file=sys.stderr)
    interrupted: KeyboardInterrupt | None = None
    pipe.start()
    try:
        try:
            last = time.monotonic()
            while pipe.running:
                hand_over.wait(0.1)
                if time.monotonic() - last >= 1.0 and sys.stderr.isatty():
                    last = time.monotonic()
                    print("\r" + status_line(pipe.figures()), end="", file=sys.stderr, flush=True)
        except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM (app/termination.py)
            interrupted = exc
            pipe.stop()
        while pipe.running:  # the loop closes the window through this thread
            hand_over.wait(0.01)
        pipe.join()
    finally:
        hand_over.finish()
        if recorder is not None:
            recorder.close()
    if sys.stderr.isatty():
        print(file=sys.stderr)
    if pipe.error and pipe.capture.frames == 0:  # the devices did not start: the message is all there is
        raise DeviceError(pipe.error)
    fig = pipe.figures()
    print_figures(fig)
    if getattr(args, "publisher", None) is not None:
        # every result has been offered (the pipeline has joined): close sends what is queued and the end message,
        # so that the summary counts every scan (before, the last one could still be on its way)
        args.publisher.close()
        print(args.publisher.summary())
    if recorder is not None:
        print(recorder.summary())
        if pipe.capture.tagged > pipe.capture.confirmed:
            print(f"{pipe.capture.tagged - pipe.capture.confirmed} tagged frame(s) next to a break not recorded")
    if pipe.latest is not None:
        save_result(pipe.latest, processor, out, session.calibration_source)
        print(f"last scan (frames {', '.join(map(str, pipe.latest.frameset.frame_ids))}) written to {out}")
    else:
        print("no depth map was produced: nothing written")
    if fusion is not None:  # after the last scan: that folder must be new when it is written
        _finish_fusion(fusion, out, label)
    if pipe.error:
        print(f"slscan {label}: stopped: {pipe.error}", file=sys.stderr)
        return 2 if pipe.latest is None else 1
    if pipe.stop_reason:
        print(f"slscan {label}: stopped cleanly: {pipe.stop_reason}", file=sys.stderr)
    if recorder is not None and recorder.stats.lost:  # a recording that lost frames is no success
        print(
            f"slscan {label}: {recorder.stats.lost} frame(s) NOT recorded: {recorder.message or 'see above'}",
            file=sys.stderr,
        )
        return 2
    if interrupted is not None:
        print(f"slscan {label}: {stopped_by(interrupted)}; stopped cleanly", file=sys.stderr)
        return exit_status(interrupted)
    return 0


def _open_fusion(session: Session, args: argparse.Namespace) -> object | None:
    if not getattr(args, "fuse", False):
        return None
    from app.fusion.live import LiveFusion
    from app.view import fusion_volume

    rng = session.depth_range_mm or (100.0, 5000.0)
    fusion = LiveFusion(session.calibration, rng, fusion_volume(session, args.volume_mm), args.voxel_mm)
    fusion.wait_ready()  # (Open3D and the tracking kernels loaded before capture: the first scans are not lost)
    return fusion


def _both(a: object, b: object) -> object:
    if a is None or b is None:
        return a or b

    def sink(res: object) -> None:
        a(res)
        b(res)

    return sink


def _finish_fusion(fusion: object, out: Path, label: str) -> None:
    from app.fusion.mesh_io import write_mesh
    from core.trajectory import write_trajectory

    fusion.stop()
    print(fusion.summary())
    s = fusion.fuser.stats
    if s.track_s:
        import numpy as np

        print(
            f"fusion: tracking {1 / np.mean(s.track_s):.1f} scans/s, integration "
            f"{(1 / np.mean(s.integrate_s)) if s.integrate_s else 0:.1f} scans/s of CPU time"
        )
    if fusion.error:
        print(f"slscan {label}: fusion stopped: {fusion.error}", file=sys.stderr)
    if s.integrated:
        out.mkdir(parents=True, exist_ok=True)
        write_trajectory(out / "model.trajectory.csv", fusion.fuser.poses)
        try:
            ply, obj = write_mesh(fusion.fuser.mesh(), out / "model.ply")
            print(f"model ({s.integrated} scans) written to {ply}, {obj}")
        except InputError as exc:
            print(f"slscan {label}: fusion: {exc}", file=sys.stderr)


def print_figures(fig: dict) -> None:
    cap = fig["capture"]
    print(
        f"frames in: {fig['frames']} ({fig['frames_per_s']:.1f}/s)  depth maps out: {fig['depth_maps']} "
        f"({fig['depth_per_s']:.1f}/s)  latency p50 {fig['latency_ms_p50']:.1f} ms, p95 {fig['latency_ms_p95']:.1f} ms"
    )
    print(
        f"per stage (median): grab+check {fig['grab_ms_p50']:.1f} ms, decode {fig['decode_ms_p50']:.1f} ms, "
        f"triangulate {fig['triangulate_ms_p50']:.1f} ms"
        + (" (in the decode pass)" if fig.get("triangulated_in_decode") else "")
    )
    print(
        f"dropped {cap['dropped']}  refused {cap['refused']}: duplicates {cap['duplicates']}, "
        f"out of order {cap['out_of_order']}, mistagged {cap['mistagged']}, untracked {cap['untracked']}; "
        f"resyncs {cap['resyncs']}; stale sets {fig['stale_sets']}, stale results {fig['stale_results']}"
    )
