"""``bench score`` and ``bench track`` run end to end on tiny cases and report what the CLI prints."""

from __future__ import annotations

import json

import pytest

from swarmpose.bench.score import bench_score, format_bench


@pytest.mark.slow
def test_bench_score_smoke():
    result = bench_score(particles=4, resolution=(16, 16), repeats=2, baseline_repeats=1, warmup=1, device="cpu",
                         lod=400)
    for key in ("hypotheses_per_s", "baseline_hypotheses_per_s", "ratio", "particles", "resolution",
                "triangles", "device", "split_ms"):
        assert key in result
    assert result["particles"] == 4 and result["resolution"] == [16, 16]
    assert result["hypotheses_per_s"] > 0 and result["baseline_hypotheses_per_s"] > 0
    assert set(result["split_ms"]) >= {"host_fk", "upload", "kernel", "readback", "total"}
    assert result["max_sum_difference"] < 1e-3  # both sides score the same hypotheses alike
    assert "hypotheses/s" in format_bench(result)


@pytest.mark.slow
def test_bench_track_splits_the_search_and_scores_the_run(capsys):
    from swarmpose.cli.main import main

    assert main(["bench", "track", "--frames", "4", "--repeats", "2", "--particles", "8", "--generations", "4",
                 "--tile", "32x32", "--json", "--quiet"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["frames"] == 4 and result["particles"] == 8 and result["generations"] == 4
    split = result["split_ms"]
    parts = split["score"] + split["joint_term"] + split["pso_update"]
    assert parts == pytest.approx(split["total"], rel=0.05)  # the parts account for the search
    assert result["hypotheses_per_s"] == pytest.approx(result["tracking_fps"] * 8 * 5)
    assert len(result["fps_runs"]) == 2 and result["fps"] > 0
    assert result["lost"] == 0 and 0 < result["mpjpe_mm"] < 250  # 4 generations: tracked, roughly
