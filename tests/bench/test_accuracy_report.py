"""The accuracy table's flip columns, the goals' misses and the flip fields over seeds, on
hand-made records."""

from __future__ import annotations

import pytest

from swarmpose.bench.accuracy import mean_over_seeds
from swarmpose.bench.accuracy_report import format_goals, format_table, goal_misses

NO_FLIP = {"flipped": 0, "sides_swapped": 0, "flips": 0, "recovery_mean_s": None, "recovery_max_s": None,
           "unrecovered": 0}


def record(motion: str, detector: str, mode: str, delta: float | None, **extra) -> dict:
    base = {"cell": f"{motion}-{detector}", "motion": motion, "shape": "male", "yaw_deg": 90, "camera_height": 1.2,
            "camera_distance": 3.0, "detector": detector, "mode": mode, "mpjpe_mm": delta, "A100": 0.9, "lost": 0,
            "facing_ok": 1.0, "detector_px": 4.0, "swapped": 0.0}
    return {**base, **extra}


RECORDS = [
    record("run", "movenet", "hybrid", 40.0, **NO_FLIP), record("run", "movenet", "joints", 80.0, **NO_FLIP),
    record("run", "blazepose", "hybrid", 60.0, flipped=5, sides_swapped=4, flips=1, recovery_mean_s=1 / 6,
           recovery_max_s=1 / 6, unrecovered=0),
    record("run", "blazepose", "joints", 70.0, **NO_FLIP),
    record("run", "simulated", "hybrid", 100.0, **NO_FLIP), record("run", "simulated", "joints", 110.0, **NO_FLIP),
    record("pick-up", "movenet", "hybrid", 45.0, flipped=3, sides_swapped=3, flips=2, recovery_mean_s=0.2,
           recovery_max_s=0.3, unrecovered=1),
    record("walk", "movenet", "hybrid", 30.0),  # made before the flip metrics
]


def test_the_goals_name_the_cells_with_a_network_that_miss_them():
    misses = goal_misses(RECORDS)
    assert misses == {"delta": ["run-blazepose"], "ratio": ["run-blazepose"],
                      "flipped": ["pick-up-movenet", "run-blazepose"]}
    lines = format_goals(RECORDS).splitlines()
    assert lines[0] == "- hybrid Δ ≤ 50 mm: 3 of 4 cells with a network; missed by run-blazepose"
    assert lines[1] == "- hybrid ≤ 0.65× joints-only: 1 of 2 cells with a network; missed by run-blazepose"
    assert lines[2].startswith("- no flipped frame (hybrid): 1 of 3 cells with a network; missed by ")


def test_the_table_shows_flipped_and_swapped_frames_and_the_recovery():
    rows = {line.split(" | ")[0] + line.split(" | ")[4]: line for line in format_table(RECORDS).splitlines()
            if line.startswith("| ") and " | 90° | " in line}
    assert "| 100 % | 5 | 4 | 0.17 / 0.17 | 4 |" in rows["| runblazepose"]
    assert "| 100 % | 0 | 0 | none | 4 |" in rows["| runmovenet"]
    assert "| 100 % | 3 | 3 | 0.20 / 0.30+ | 4 |" in rows["| pick-upmovenet"], "the last flip lasted to the end"
    assert "| 100 % | – | – | – | 4 |" in rows["| walkmovenet"], "a record from before the flip metrics"
    assert "'+': a flip still on at the last frame" in format_table(RECORDS)


def test_flips_over_seeds_average_the_counts_and_keep_the_longest_recovery():
    seeds = [record("run", "movenet", "hybrid", 40.0, **NO_FLIP),
             record("run", "movenet", "hybrid", 50.0, seed=1, flipped=6, sides_swapped=2, flips=2,
                    recovery_mean_s=0.25, recovery_max_s=0.4, unrecovered=1),
             record("run", "movenet", "hybrid", 60.0, seed=2, flipped=3, sides_swapped=3, flips=1,
                    recovery_mean_s=0.1, recovery_max_s=0.1, unrecovered=0)]
    merged = mean_over_seeds(seeds)[0]
    assert merged["flipped"] == pytest.approx(3.0) and merged["sides_swapped"] == pytest.approx(5 / 3)
    assert merged["flips"] == pytest.approx(1.0) and merged["unrecovered"] == pytest.approx(1 / 3)
    assert merged["recovery_mean_s"] == pytest.approx(0.175), "over the seeds that had a flip"
    assert merged["recovery_max_s"] == pytest.approx(0.4)
    old = mean_over_seeds([record("walk", "movenet", "hybrid", 30.0), record("walk", "movenet", "hybrid", 40.0,
                                                                             seed=1)])[0]
    assert "flipped" not in old and "recovery_max_s" not in old, "records from before the metrics gain none"
