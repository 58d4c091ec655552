"""The frame budget's sizing against hand computation."""

from __future__ import annotations

from swarmpose.tracking.budget import MIN_GENERATIONS, SMOOTHING, FrameBudget


def test_no_budget_or_no_measurement_keeps_the_configured_search():
    assert FrameBudget().plan(100.0, 64, 64, 60) == (64, 60)
    assert FrameBudget(0.04, 20.0).plan(0.0, 64, 64, 60) == (64, 60)


def test_the_time_left_is_shared_three_to_one_between_swarm_and_polish():
    budget = FrameBudget(ms_per_pose=0.05, other_ms=20.0)  # 80 ms left: 60 for the swarm, 20 for the polish
    # 60 ms / (64 poses x 0.05 ms) = 18.75 scored sets: 18, less generation 0's; 20 ms / (32 x 0.05) = 12.5 rounds
    assert budget.plan(100.0, 64, 64, 60) == (17, 12)
    assert budget.plan(100.0, 64, 10, 5) == (10, 5)  # never more than configured
    assert budget.plan(10.0, 64, 64, 60) == (MIN_GENERATIONS, 0)  # nothing left: the least swarm
    assert budget.plan(10.0, 8, 4, 2) == (4, 0)  # fewer configured than the least: the configured ones
    assert budget.plan(100.0, 64, 64, 0)[0] == 24  # no polish: all 80 ms to the swarm, 25 sets less generation 0


def test_the_cost_model_is_a_running_mean():
    budget = FrameBudget()
    budget.record(search_ms=100.0, poses=2000, total_ms=150.0)
    assert (budget.ms_per_pose, budget.other_ms) == (0.05, 50.0)
    budget.record(search_ms=60.0, poses=2000, total_ms=80.0)
    assert abs(budget.ms_per_pose - (0.05 + SMOOTHING * (0.03 - 0.05))) < 1e-12
    assert abs(budget.other_ms - (50.0 + SMOOTHING * (20.0 - 50.0))) < 1e-12


def test_lean_frames_and_the_start_only_with_a_budget():
    from swarmpose.tracking.budget import LEAN_BELOW, START_SHARE, lean_frame, start_budget

    assert not lean_frame(0.0, 6) and lean_frame(100.0, LEAN_BELOW - 1) and not lean_frame(100.0, LEAN_BELOW)
    assert start_budget(64, 0.0, 64, 64) == (64, 64) and start_budget(64, 0.0, 32, 128) == (64, 128)
    least = int(64 * START_SHARE)  # live: the share of start_budget, whatever the frame's search runs
    assert start_budget(64, 100.0, 64, 64) == (least, least) and start_budget(64, 100.0, 128, 128) == (least, least)


def test_the_live_budget_on_auto_is_nine_tenths_of_the_cameras_frame_period():
    from swarmpose.tracking.budget import live_budget_ms

    assert abs(live_budget_ms(None, 1 / 30) - 30.0) < 1e-9  # 0.9 x 33.3 ms
    assert abs(live_budget_ms(None, 1 / 15) - 60.0) < 1e-9
    assert live_budget_ms(45.0, 1 / 30) == 45.0 and live_budget_ms(0.0, 1 / 30) == 0.0  # set: as set
