"""``bench_score`` runs end to end on a tiny case and reports what the CLI prints."""

from __future__ import annotations

from swarmpose.bench.score import bench_score, format_bench


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
