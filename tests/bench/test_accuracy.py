"""The accuracy benchmark's regression subset: the MakeHuman walk seen from the side and from
behind and jumping jacks from behind, MoveNet (the real network) on the rendered colour, scored
against the ground truth.

Before the start tried several facings, hybrid locked into a mirrored pose on the side view
(Δ 219 mm, torso facing 151° off); before young tracks re-checked their facing, the jumping
jacks stayed mirrored for 20 frames after MoveNet swapped sides on the first (294 mm, 30 % of
frames facing right; 55 mm and 90 % now). These bounds keep both from coming back.
"""

from __future__ import annotations

import json

import pytest
from conftest import ASSETS, needs_assets

from swarmpose.bench.accuracy import mean_over_seeds, run_matrix
from swarmpose.bench.matrix import cells, sequences
from swarmpose.cli.main import main

SETTINGS = {"particles": 32, "generations": 32}
FRAMES = 20
BOUND_MM = {("walk", 90): 90.0, ("walk", 180): 60.0, ("jumping-jacks", 180): 100.0}
"""Hybrid Δ bound per motion and yaw (the walk: measured 71 and 47 mm at p = g = 32, 20 frames;
85 and 48 mm before the two-stage start and the penetration term, 215 and 45 mm with a start
that did not converge; the jumping jacks: see the module doc and BENCHMARKS.md)."""
RATIO = {("walk", 90): 0.65, ("walk", 180): 0.65, ("jumping-jacks", 180): 0.75}
"""Bound on hybrid Δ / joints-only Δ (measured 0.54, 0.55 and 0.61)."""
FACING_OK = {("walk", 90): 0.9, ("walk", 180): 0.9, ("jumping-jacks", 180): 0.8}
"""Share of hybrid frames with the torso facing within 30°: the jumping jacks' first frame
(and at p = g = 32 its second) is mirrored until the re-check of the young track replaces it."""


@pytest.fixture(scope="module")
def regression(tmp_path_factory):
    out = tmp_path_factory.mktemp("accuracy")
    records = run_matrix(out, subset="regression", modes=("hybrid", "joints"), frames=FRAMES, tracker=SETTINGS,
                         assets=ASSETS, progress=False)
    return out, records


@pytest.mark.slow
@needs_assets
def test_side_and_back_views_with_movenet_hold(regression):
    _, records = regression
    by = {(r["motion"], r["yaw_deg"], r["mode"]): r for r in records}
    assert sorted(by) == sorted((*cell, mode) for cell in BOUND_MM for mode in ("hybrid", "joints"))
    for (motion, yaw), bound in BOUND_MM.items():
        hybrid, joints = by[motion, yaw, "hybrid"], by[motion, yaw, "joints"]
        assert hybrid["frames"] == FRAMES and hybrid["detector"] == "movenet"
        assert hybrid["mpjpe_mm"] <= bound, hybrid
        assert hybrid["facing_ok"] >= FACING_OK[motion, yaw], f"torso facing within 30° on too few frames: {hybrid}"
        assert hybrid["lost"] == 0
        assert hybrid["mpjpe_mm"] < RATIO[motion, yaw] * joints["mpjpe_mm"], (hybrid, joints)
        assert hybrid["detector_px"] < 15, "MoveNet on the rendered colour finds the limbs within a few pixels"


@needs_assets
def test_the_command_resumes_and_writes_table_and_heat_map(regression):
    out, records = regression
    results = sorted((out / "results").glob("*.json"))
    stamps = [p.stat().st_mtime_ns for p in results]
    argv = ["bench", "accuracy", "--subset", "regression", "--modes", "hybrid,joints", "--frames", str(FRAMES),
            "--particles", "32", "--generations", "32", "--assets", str(ASSETS), "--out", str(out), "--quiet"]
    assert main(argv) == 0
    assert [p.stat().st_mtime_ns for p in results] == stamps, "finished cells are read back, not run again"
    assert json.loads((out / "records.json").read_text()) == records
    table = (out / "table.md").read_text()
    assert "| walk | male | 90° |" in table and "| movenet | 180° |" in table
    assert (out / "heatmap.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_matrix_crosses_every_yaw_with_every_detector_and_motion_with_three_yaws():
    full = cells("full")
    assert len(full) == 45 and len({c.name for c in full}) == 45
    assert {(c.sequence.yaw_deg, c.detector) for c in full} == {(y, d) for y in (0, 45, 90, 135, 180)
                                                                 for d in ("simulated", "movenet", "blazepose")}
    yaws_of = {}
    for seq in sequences("full"):
        yaws_of.setdefault(seq.motion, set()).add(seq.yaw_deg)
    assert all(len(y) == 3 for y in yaws_of.values()) and len(yaws_of) == 5
    assert len({s.shape for s in sequences("full")}) == 4
    assert len({(s.camera_height, s.camera_distance) for s in sequences("full")}) == 2


@needs_assets
def test_a_sequence_too_short_for_the_run_is_rendered_again(tmp_path):
    from swarmpose.bench.accuracy import make_sequence

    seq = sequences("regression")[0]
    folder = tmp_path / seq.name
    make_sequence(seq, folder, 2, ASSETS)
    (tmp_path / f"{seq.name}.partial").mkdir()  # what an interrupted rendering leaves
    make_sequence(seq, folder, 3, ASSETS)
    assert len((folder / "groundtruth.jsonl").read_text().splitlines()) == 3
    assert len(list((folder / "depth").glob("*.png"))) == 3


@pytest.mark.slow
@needs_assets
def test_seeds_track_each_cell_again_and_the_table_shows_their_mean(regression):
    out, records = regression
    first = {r["cell"]: r for r in records if r["mode"] == "joints"}
    seed0 = sorted((out / "results").glob("*-joints.json"))
    stamps = [p.stat().st_mtime_ns for p in seed0]
    argv = ["bench", "accuracy", "--subset", "regression", "--modes", "joints", "--frames", str(FRAMES),
            "--particles", "32", "--generations", "32", "--assets", str(ASSETS), "--out", str(out), "--quiet",
            "--seeds", "2"]
    assert main(argv) == 0
    second = {p.name: json.loads(p.read_text()) for p in (out / "results").glob("*-joints-seed1.json")}
    assert len(second) == len(first) and all(r["seed"] == 1 for r in second.values())
    again = json.loads((out / "records.json").read_text())
    assert [r for r in again if r.get("seed") is None] == [first[c] for c in first]
    assert [p.stat().st_mtime_ns for p in seed0] == stamps, "seed 0's records are read back, not run again"
    seed1 = sorted((out / "results").glob("*-joints-seed1.json"))
    stamps1 = [p.stat().st_mtime_ns for p in seed1]
    assert main(argv) == 0
    assert [p.stat().st_mtime_ns for p in seed1] == stamps1, "and so are seed 1's on the next run"
    assert any(r["mpjpe_mm"] != first[r["cell"]]["mpjpe_mm"] for r in second.values()), "another seed, another run"
    table = (out / "table.md").read_text()
    assert "hybrid spread over seeds" in table
    for record in second.values():  # Δ per mode (hybrid, joints, depth, lift), then hybrid's spread
        mean = (record["mpjpe_mm"] + first[record["cell"]]["mpjpe_mm"]) / 2
        assert f"| movenet | – | {mean:.0f} | – | – | – |" in table, (mean, table)


def test_mean_over_seeds_averages_per_cell_and_mode():
    base = {"cell": "c", "motion": "walk", "frames": 20}
    records = [{**base, "mode": "hybrid", "mpjpe_mm": 40.0, "A100": 0.9, "lost": 0, "facing_deg": 10.0,
                "facing_ok": 1.0, "fps": 8.0, "detector_px": 4.0, "swapped": 0.0},
               {**base, "mode": "hybrid", "seed": 1, "mpjpe_mm": 70.0, "A100": 0.7, "lost": 3, "facing_deg": 20.0,
                "facing_ok": 0.5, "fps": 6.0, "detector_px": 6.0, "swapped": 0.5},
               {**base, "mode": "lift", "mpjpe_mm": 55.0, "A100": 0.8, "lost": 0, "facing_deg": None,
                "facing_ok": 0.0, "fps": 30.0, "detector_px": 4.0, "swapped": 0.0},
               {**base, "mode": "depth", "mpjpe_mm": None, "A100": 0.0, "lost": 20, "facing_deg": None,
                "facing_ok": 0.0, "fps": 9.0, "detector_px": None, "swapped": None},
               {**base, "mode": "depth", "seed": 1, "mpjpe_mm": 80.0, "A100": 0.5, "lost": 2, "facing_deg": 30.0,
                "facing_ok": 0.4, "fps": 9.0, "detector_px": None, "swapped": None}]
    merged = {r["mode"]: r for r in mean_over_seeds(records)}
    assert merged["hybrid"] == {**base, "mode": "hybrid", "mpjpe_mm": 55.0, "A100": 0.8, "lost": 1.5,
                                "facing_deg": 15.0, "facing_ok": 0.75, "fps": 7.0, "detector_px": 5.0,
                                "swapped": 0.25, "seeds": 2, "mpjpe_spread_mm": 30.0}
    assert merged["lift"]["seeds"] == 1 and merged["lift"]["mpjpe_spread_mm"] == 0.0
    assert merged["lift"]["facing_deg"] is None
    assert merged["depth"]["mpjpe_mm"] is None and merged["depth"]["mpjpe_spread_mm"] is None, "a seed with no Δ"
    assert merged["depth"]["lost"] == 11.0
