"""`slscan dump --repair` cannot destroy: any key order, no path through a symlink, nothing deleted, the tag kept."""

from __future__ import annotations

import os

import numpy as np
import pytest
import yaml

from app.cli import main
from core.calibration import Calibration
from core.dump import INDEX, ORPHANS, DumpWriter, read_dump, repair_dump
from core.errors import InputError
from core.patterns import two_shot_patterns


def write_dump(folder, n: int = 5) -> list[np.ndarray]:
    """A dump of n random 64x48 frames, patterns alternating, frame ids from 10, with a calibration."""
    K = [[500, 0, 31.5], [0, 500, 23.5], [0, 0, 1]]
    cal = Calibration((64, 48), K, [0] * 5, (128, 96), K, [0] * 5, np.eye(3), [-100, 0, 0], color_mixing=np.eye(3))
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 256, (48, 64, 3), dtype=np.uint8) for _ in range(n)]
    with DumpWriter(folder, two_shot_patterns((128, 96)), cal, depth_range_mm=(300, 900)) as w:
        for i, f in enumerate(frames):
            w.add(f, pattern=i % 2, frame_id=10 + i, timestamp_ns=1000 * i)
    return frames


def _frames(folder) -> list[tuple[int, int, int]]:
    return [(f.frame_id, f.pattern, f.timestamp_ns) for f in read_dump(folder).frames]


def test_repair_of_a_valid_dump_in_another_key_order_keeps_it_readable(tmp_path):
    d = tmp_path / "d"
    frames = write_dump(d)
    before = _frames(d)
    meta = yaml.safe_load((d / INDEX).read_text())
    (d / INDEX).write_text(yaml.safe_dump(meta, sort_keys=True))  # as another tool writes it: frames not last
    old = (d / INDEX).read_bytes()
    report = repair_dump(d)
    assert report.frames == 5 and report.dropped_entries == 0 and report.orphaned == 0
    assert _frames(d) == before
    again = read_dump(d)
    assert again.depth_range_mm() == (300, 900) and again.calibration().camera_size == (64, 48)
    for i, f in enumerate(frames):
        assert np.array_equal(again.load_frame(i), f)
    assert (d / "dump.yaml.bak").read_bytes() == old  # the old index kept, byte for byte
    repair_dump(d)
    assert (d / "dump.yaml.bak.1").is_file() and (d / "dump.yaml.bak").read_bytes() == old  # never overwritten


def test_a_frame_whose_rename_a_kill_prevented_is_recovered_with_its_tag(tmp_path):
    d = tmp_path / "d"
    frames = write_dump(d)
    # the writer's state between the index entry and the rename: the last frame complete under its temporary name
    os.replace(d / "frames/000004.png", d / "frames/000004.tmp.png")
    dump = read_dump(d)
    assert len(dump.frames) == 4 and dump.dropped_tail == 1
    report = repair_dump(d)
    assert report.recovered == 1 and report.frames == 5 and report.dropped_entries == 0
    assert _frames(d) == [(10 + i, i % 2, 1000 * i) for i in range(5)]
    assert np.array_equal(read_dump(d).load_frame(4), frames[4])
    assert not list((d / "frames").glob("*.tmp.png"))


def test_partial_and_unindexed_frames_move_to_orphans_not_deleted(tmp_path):
    d = tmp_path / "d"
    write_dump(d)
    data = (d / "frames/000004.png").read_bytes()
    (d / "frames/000004.png").unlink()
    (d / "frames/000004.tmp.png").write_bytes(data[: len(data) // 2])  # a write cut short: its entry is dropped
    (d / "frames/000009.png").write_bytes(data)  # a complete frame with no entry
    report = repair_dump(d)
    assert report.frames == 4 and report.dropped_entries == 1 and report.recovered == 0 and report.orphaned == 2
    assert sorted(p.name for p in (d / ORPHANS).iterdir()) == ["000004.tmp.png", "000009.png"]
    assert (d / ORPHANS / "000009.png").read_bytes() == data
    assert sorted(p.name for p in (d / "frames").iterdir()) == [f"{i:06d}.png" for i in range(4)]
    assert read_dump(d).dropped_tail == 0


def test_repair_through_a_symlinked_frames_folder_touches_nothing_outside(tmp_path, capsys):
    d = tmp_path / "d"
    write_dump(d)
    elsewhere = tmp_path / "elsewhere"
    os.replace(d / "frames", elsewhere)
    (elsewhere / "precious.png").write_bytes(b"not a frame of this dump")
    os.symlink(elsewhere, d / "frames")
    with pytest.raises(InputError, match="symlink"):
        repair_dump(d)
    assert main(["dump", "--repair", str(d)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "frames" in err[0] and "symlink" in err[0]
    assert (elsewhere / "precious.png").read_bytes() == b"not a frame of this dump"
    assert len(list(elsewhere.iterdir())) == 6 and not (d / "dump.yaml.bak").exists()


def test_a_frame_file_that_is_a_symlink_out_of_the_dump_is_refused(tmp_path):
    d = tmp_path / "d"
    write_dump(d)
    outside = tmp_path / "outside.png"
    os.replace(d / "frames/000002.png", outside)
    os.symlink(outside, d / "frames/000002.png")
    with pytest.raises(InputError, match=r"frames\[2\]\.file.*symlink that leaves the dump folder"):
        read_dump(d)
    with pytest.raises(InputError, match="symlink"):
        repair_dump(d)
    assert outside.is_file()


def striped_frames(n: int) -> list[np.ndarray]:
    """n 64x48 frames of a two-shot scene: stripes in G and B inverted from frame to frame, over a fixed texture,
    with a little noise (what a camera films of a still object)."""
    rng = np.random.default_rng(1)
    texture = rng.integers(40, 120, (48, 64, 3)).astype(np.int16)
    stripes = np.zeros((48, 64, 3), np.int16)
    stripes[:, (np.arange(64) // 3) % 2 == 0, 1] = 100
    stripes[:, (np.arange(64) // 5) % 2 == 0, 2] = 100
    frames = []
    for i in range(n):
        lit = stripes if i % 2 == 0 else 100 * (stripes == 0) * np.array([0, 1, 1])
        frames.append(np.clip(texture + lit + rng.integers(-3, 4, texture.shape), 0, 255).astype(np.uint8))
    return frames


def write_killed_before_the_entry(folder, frames: list[np.ndarray], last: np.ndarray) -> None:
    """A dump of frames whose writer was killed with `last` complete under its temporary name, its entry unwritten."""
    K = [[500, 0, 31.5], [0, 500, 23.5], [0, 0, 1]]
    cal = Calibration((64, 48), K, [0] * 5, (128, 96), K, [0] * 5, np.eye(3), [-100, 0, 0])
    with DumpWriter(folder, two_shot_patterns((128, 96)), cal) as w:
        for i, f in enumerate([*frames, last]):
            w.add(f, pattern=i % 2, frame_id=10 + i, timestamp_ns=1000 * i)
    lines = (folder / INDEX).read_text().splitlines(keepends=True)
    (folder / INDEX).write_text("".join(lines[:-1]))  # the entry of the last frame never written
    n = len(frames)
    os.replace(folder / f"frames/{n:06d}.png", folder / f"frames/{n:06d}.tmp.png")


def test_a_complete_frame_without_its_entry_is_reindexed_from_its_content(tmp_path):
    d = tmp_path / "d"
    frames = striped_frames(6)
    write_killed_before_the_entry(d, frames[:5], frames[5])
    assert len(read_dump(d).frames) == 5
    report = repair_dump(d)
    assert report.recovered == 1 and report.reindexed == 1 and report.orphaned == 0
    dump = read_dump(d)
    assert _frames(d) == [(10 + i, i % 2, 1000 * i) for i in range(6)]  # pattern 1 was due, and it saw pattern 1
    assert dump.frames[5].recovered == "content" and not dump.frames[4].recovered
    assert np.array_equal(dump.load_frame(5), frames[5])
    repair_dump(d)  # the mark survives a second repair
    assert read_dump(d).frames[5].recovered == "content"


@pytest.mark.parametrize("content", ["wrong pattern", "noise"])
def test_a_frame_whose_content_does_not_tell_its_pattern_goes_to_orphans(tmp_path, content):
    d = tmp_path / "d"
    frames = striped_frames(6)
    last = frames[4] if content == "wrong pattern" else np.random.default_rng(2).integers(0, 256, (48, 64, 3), np.uint8)
    write_killed_before_the_entry(d, frames[:5], last)
    report = repair_dump(d)
    assert report.reindexed == 0 and report.orphaned == 1 and report.frames == 5
    assert (d / ORPHANS / "000005.tmp.png").is_file()
