"""``swarmpose bench still`` (issue 53): its plan's checks, and its report of a tiny run against the
same sequence tracked by ``swarmpose track`` and measured by hand from ``poses.csv``."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from swarmpose.bench.still_plan import StillPlan
from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.cli.main import main
from swarmpose.core.errors import ConfigError

TINY_SEARCH = ("--particles", "8", "--generations", "4", "--polish", "0")
TINY = ("--body", "builtin", "--clip", "builtin:walk", "--shapes", "male", "--yaws", "0", "--detectors", "simulated",
        "--hold", "0.5", "--moving", "0.8", "--settle", "0.1", *TINY_SEARCH)
"""15 still frames (the first 3 left out), then 24 of the built-in walk."""


@pytest.mark.parametrize(("plan", "needle"), [
    (StillPlan(hold_s=0.3), "leaves fewer than 2 still frames"),
    (StillPlan(moving_s=0.5), "too short for the lag"),
    (StillPlan(detectors=("openpose",)), "unknown detector 'openpose'"),
    (StillPlan(shapes=()), "at least one shape"),
])
def test_a_plan_too_short_to_measure_is_refused(plan, needle):
    with pytest.raises(ConfigError, match=needle):
        plan.validate()


def test_bad_flags_exit_2(tmp_path, capsys):
    assert main(["bench", "still", "--out", str(tmp_path), "--hold", "0.2", *TINY[:10]]) == 2
    assert "--hold 0.2 s leaves fewer than 2 still frames" in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:
        main(["bench", "still", "--out", str(tmp_path), "--yaws", "front"])
    assert info.value.code == 2


def _csv_joints(path) -> np.ndarray:
    """(F, J, 3) m of body 0 from a poses.csv (NaN where it has none)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return np.array([[[float(r[f"{j}_{a}"] or "nan") for a in "xyz"] for j in EVAL_JOINTS] for r in rows])


@pytest.mark.slow
def test_the_report_of_a_tiny_run_matches_its_sequence_tracked_on_its_own(tmp_path, capsys):
    out = tmp_path / "still"
    assert main(["bench", "still", "--out", str(out), *TINY, "--json", "--quiet"]) == 0
    report = json.loads(capsys.readouterr().out)
    rows = {r["smoothing"]: r for r in report["rows"]}
    assert set(rows) == {"off", "one-euro", "centred"} and len(report["summary"]) == 3
    assert rows["off"]["off_agree_mm"] == 0.0  # the smoothed runs searched the same track
    assert all(r["lag_ms"] is not None and r["jitter_mm"] > 0 for r in rows.values())
    # the sequence as `track` sees it, unsmoothed, its jitter over the still frames 3..14 by hand
    sequence = out / "sequences" / "still-male-yaw000"
    assert main(["track", str(sequence), "--out", str(tmp_path / "track"), "--detector", "simulated", "--body",
                 "builtin", "--shape", "male", "--max-people", "1", "--no-overlay", "--quiet", *TINY_SEARCH]) == 0
    capsys.readouterr()
    joints = _csv_joints(tmp_path / "track" / "poses.csv")
    assert joints.shape == (39, len(EVAL_JOINTS), 3)
    still = joints[3:15]
    by_hand = 1000.0 * np.sqrt(((still - still.mean(axis=0)) ** 2).sum(axis=2).mean(axis=0))
    assert np.allclose(rows["off"]["jitter_per_joint_mm"], by_hand, atol=0.05)
    worst = EVAL_JOINTS.index(rows["off"]["jitter_worst"])  # a joint as unsteady as the worst (ties: the CSV's mm)
    assert by_hand[worst] == pytest.approx(by_hand.max(), abs=0.05)
    truth = [json.loads(line) for line in (sequence / "groundtruth.jsonl").read_text().splitlines()]
    true = np.array([[t["joints3d"][j] for j in EVAL_JOINTS] for t in truth])
    assert np.array_equal(true[:15], np.repeat(true[:1], 15, axis=0))  # still for 0.5 s, then the walk
    assert rows["off"]["still_delta_mm"] == pytest.approx(
        1000.0 * np.linalg.norm(still - true[3:15], axis=2).mean(), abs=0.05)
    # run again: every record is read back
    assert main(["bench", "still", "--out", str(out), *TINY, "--json", "--quiet"]) == 0
    assert json.loads(capsys.readouterr().out)["rows"] == report["rows"]


def test_both_tables_have_as_many_cells_in_every_line_as_their_header():
    from swarmpose.bench.still_report import format_rows, format_summary

    row = {"sequence": "still-front", "detector": "movenet", "smoothing": "off", "jitter_mm": 9.3,
           "jitter_max_mm": 20.1, "jitter_worst": "left_wrist", "still_delta_mm": 21.0, "lag_ms": 5.0,
           "onset_delta_mm": 30.2, "moving_delta_mm": None}
    for table, leading in ((format_summary([row]), 2), (format_rows([row]), 3)):
        lines = table.splitlines()
        assert len({line.count("|") for line in lines}) == 1, table
        assert lines[2].split(" | ")[leading:leading + 2] == ["9.3", "20.1 (left_wrist)"]
        assert lines[2].endswith("| 30.2 | – |")
