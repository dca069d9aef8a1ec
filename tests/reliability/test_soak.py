"""`slscan bench --soak`: a few seconds of it, figures checked for what they claim (the real run is in the report)."""

from __future__ import annotations

import pytest

from app.bench.soak import format_table, soak
from app.cli import main


@pytest.mark.slow
def test_short_soak_reports_consistent_figures():
    # A first short session starts the libraries' own thread pools (BLAS, numba), which stay by design;
    # the figures that must not grow are those of a session in a process already warmed up.
    soak(0.02, sample_s=1.0, sim_overrides={"camera_size": [320, 240]})
    fig = soak(0.06, sample_s=1.0, sim_overrides={"camera_size": [320, 240]})
    assert fig["error"] == ""
    assert fig["frames_in"] >= 30 and fig["depth_maps_out"] >= 1
    assert fig["sets_checked"] == fig["depth_maps_out"]  # every decoded set was checked against the truth
    assert fig["mispaired"] == 0 and fig["tail_mispaired"] == 0
    # real /proc figures; no order between them: in a long pytest process the rig may reuse memory
    # freed by earlier tests, and the allocator may hand memory back in between (seen once in three runs)
    assert fig["rss_mb_start"] > 10 and fig["rss_mb_before"] > 10
    assert fig["threads_start"] > fig["threads_before"]  # acquisition, decode, projector threads
    assert fig["threads_after"] <= fig["threads_before"] + 1 and fig["fds_after"] <= fig["fds_before"] + 1
    assert len(fig["samples"]) >= 3 and fig["samples"][-1]["frames"] > 0
    assert "MISPAIRED" in format_table([fig])


def test_soak_refuses_a_bad_length(capsys):
    assert main(["bench", "--soak", "--minutes", "0"]) == 2
    assert "--minutes" in capsys.readouterr().err
