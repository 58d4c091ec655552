"""``swarmpose bench utdmhad`` and ``swarmpose eval utdmhad:...`` on the real UTD-MHAD Kinect sequences."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import ASSETS, needs_assets

from swarmpose.bench.utdmhad import add_offset_scores, format_table, run_utdmhad, sequences
from swarmpose.cli.main import main
from swarmpose.core.errors import ConfigError
from swarmpose.sim.evaluate import joint_errors, summarise
from swarmpose.sources.utdmhad import UtdMhadSource
from swarmpose.sources.utdmhad_sync import DEPTH_LAG_FRAMES

UTD = ASSETS / "rgbd" / "utd_mhad"
FAST = ["--particles", "8", "--generations", "4", "--quiet"]


@needs_assets
def test_the_benchmark_covers_81_sequences_of_three_subjects():
    found = sequences(ASSETS)
    assert len(found) == 81
    assert {p.name.split("_")[1] for p in found} == {"s1", "s2", "s3"}
    assert [p.name for p in sequences(ASSETS, ("s2",), (3, 27))] == ["a3_s2_t1_depth.mat", "a27_s2_t1_depth.mat"]
    with pytest.raises(ConfigError, match="no UTD-MHAD depth files"):
        sequences(ASSETS, ("s9",))


def test_offset_scores_remove_a_constant_per_joint_difference_learnt_on_the_other_subjects():
    rng = np.random.default_rng(0)
    truths = [rng.normal(size=(5, 14, 3)) for _ in range(3)]
    offset = rng.normal(scale=0.05, size=(14, 3))
    arrays = [(t + offset, t) for t in truths]
    records = [{"mode": "hybrid", "detector": "simulated", "shape": "default", "subject": s}
               for s in ("s1", "s2", "s3")]
    add_offset_scores(records, arrays)
    assert all(r["mpjpe_offset_mm"] == pytest.approx(0.0, abs=1e-9) for r in records)
    # an offset seen only on one subject is not learnt from it for that subject
    arrays[0] = (truths[0] + 2 * offset, truths[0])
    add_offset_scores(records, arrays)
    by_hand = summarise(joint_errors(truths[0] + offset, truths[0]))["mpjpe_mm"]
    assert records[0]["mpjpe_offset_mm"] == pytest.approx(by_hand)


@pytest.mark.slow
@needs_assets
def test_the_benchmark_tracks_scores_and_resumes(tmp_path):
    tracker = {"particles": 8, "generations": 4}
    kwargs = dict(modes=("hybrid", "lift"), detectors=("simulated",), frames=4, tracker=tracker,
                  subjects=("s1", "s2"), actions=(23,), progress=False)
    records = run_utdmhad(tmp_path, **kwargs)
    assert len(records) == 4
    for record in records:
        assert record["frames"] == 4 and np.isfinite(record["mpjpe_mm"]) and record["mpjpe_mm"] < 250
        assert record["mpjpe_offset_mm"] is not None
    stored = sorted((tmp_path / "results").glob("*.json"))
    assert len(stored) == 4
    with np.load(stored[0].with_suffix(".npz")) as data:
        record = json.loads(stored[0].read_text())
        by_hand = summarise(joint_errors(data["estimates"], data["truth"]))["mpjpe_mm"]
        assert by_hand == pytest.approx(record["mpjpe_mm"])
    stamps = [p.stat().st_mtime_ns for p in stored]
    again = run_utdmhad(tmp_path, **kwargs)
    assert [p.stat().st_mtime_ns for p in stored] == stamps
    assert [r["mpjpe_mm"] for r in again] == [r["mpjpe_mm"] for r in records]
    table = format_table(again)
    assert "a23 walk" in table and "hybrid simulated default" in table and "**all**" in table
    assert {r["lag_frames"] for r in again} == {DEPTH_LAG_FRAMES}
    files_pairing = run_utdmhad(tmp_path, **{**kwargs, "modes": ("lift",)}, lag_frames=0.0)  # not resumed
    assert [p.stat().st_mtime_ns for p in stored] != stamps
    lift = next(r for r in records if r["mode"] == "lift" and r["subject"] == "s1")
    assert next(r for r in files_pairing if r["subject"] == "s1")["mpjpe_mm"] != lift["mpjpe_mm"]
    # each record was scored against the source's ground truth at its own lag
    path = UTD / "depth" / "a23_s1_t1_depth.mat"
    for variant, lag in (("lift-simulated-default", 0.0), ("hybrid-simulated-default", DEPTH_LAG_FRAMES)):
        with np.load(tmp_path / "results" / f"a23_s1_t1-{variant}.npz") as data:
            np.testing.assert_array_equal(data["truth"], UtdMhadSource(path, lag_frames=lag).ground_truth.joints3d[:4])


@pytest.mark.slow
@needs_assets
def test_eval_runs_on_a_utdmhad_file_with_its_defaults(capsys):
    path = UTD / "depth" / "a23_s1_t1_depth.mat"
    assert main(["eval", f"utdmhad:{path}", "--json", "--frames", "3"] + FAST) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["frames"] == 3 and result["detector"] == "movenet" and result["mpjpe_mm"] < 250  # auto: a network


def test_eval_refuses_a_mat_file_that_is_not_utdmhad(tmp_path, capsys):
    bad = tmp_path / "a1_s1_t1_depth.mat"
    bad.write_bytes(b"\x00" * 200)
    assert main(["eval", str(bad), "--quiet"]) == 2
    assert "a1_s1_t1_depth.mat" in capsys.readouterr().err


@pytest.mark.slow
@needs_assets
def test_seeds_track_each_sequence_again_and_resume(tmp_path):
    """Two seeds: seed 0's files keep their names, seed 1's carry ``-seed1`` and the seed; the two
    runs differ (the PSO draws otherwise); the summary averages every record of the variant and a
    second call reads them all back."""
    from swarmpose.bench.utdmhad import summary

    kwargs = dict(modes=("hybrid",), detectors=("simulated",), frames=4, tracker={"particles": 8, "generations": 4},
                  subjects=("s1", "s2"), actions=(23,), progress=False, seeds=2)
    records = run_utdmhad(tmp_path, **kwargs)
    names = sorted(p.name for p in (tmp_path / "results").glob("*.json"))
    assert names == ["a23_s1_t1-hybrid-simulated-default-seed1.json", "a23_s1_t1-hybrid-simulated-default.json",
                     "a23_s2_t1-hybrid-simulated-default-seed1.json", "a23_s2_t1-hybrid-simulated-default.json"]
    by_seed = {(r["sequence"], r.get("seed", 0)): r for r in records}
    assert by_seed[("a23_s1_t1", 1)]["seed"] == 1 and "seed" not in by_seed[("a23_s1_t1", 0)]
    assert by_seed[("a23_s1_t1", 0)]["mpjpe_mm"] != by_seed[("a23_s1_t1", 1)]["mpjpe_mm"]
    overall = summary(records)["hybrid-simulated-default"]
    assert overall["sequences"] == 2 and overall["seeds"] == 2
    assert overall["mpjpe_mm"] == pytest.approx(np.mean([r["mpjpe_mm"] for r in records]))
    stamps = [p.stat().st_mtime_ns for p in sorted((tmp_path / "results").glob("*.json"))]
    again = run_utdmhad(tmp_path, **kwargs)
    assert [p.stat().st_mtime_ns for p in sorted((tmp_path / "results").glob("*.json"))] == stamps
    assert [r["mpjpe_mm"] for r in again] == [r["mpjpe_mm"] for r in records]
    with pytest.raises(ConfigError, match="--seeds"):
        run_utdmhad(tmp_path, **{**kwargs, "seeds": 0})
