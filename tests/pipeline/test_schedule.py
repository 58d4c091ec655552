"""Just-in-time detection: how long detection waits, against the median and mean worked out by hand."""

from __future__ import annotations

import time

import pytest

from swarmpose.pipeline.schedule import RECENT_FRAMES, JustInTime
from swarmpose.tracking.budget import SMOOTHING


def test_no_wait_until_both_durations_are_known_and_the_tracker_is_busy():
    timing = JustInTime()
    assert timing.wait_s() == 0.0
    timing.detected(0.02)
    timing.tracking()
    assert timing.wait_s() == 0.0  # no tracking time measured yet
    timing.tracked()
    assert timing.wait_s() == 0.0  # the tracker is idle: take the next frame now


def test_detection_waits_for_the_tracker_less_its_own_time(monkeypatch):
    now = [100.0]
    monkeypatch.setattr(time, "monotonic", lambda: now[0])
    timing = JustInTime()
    timing.tracking()
    now[0] += 0.10
    timing.tracked()  # tracking takes 100 ms
    timing.detected(0.03)
    timing.tracking()
    now[0] += 0.01
    assert timing.wait_s() == pytest.approx(0.10 - 0.03 - 0.01)
    now[0] += 0.09
    timing.tracked()  # a 100 ms frame again
    timing.detected(0.05)
    assert timing.detect_s[False] == pytest.approx(0.03 + SMOOTHING * (0.05 - 0.03))
    timing.tracking()
    now[0] += 0.5
    assert timing.wait_s() == 0.0  # overdue: never negative


def test_a_waiting_detection_wakes_when_the_tracker_finishes_early():
    import threading

    timing = JustInTime()
    timing.track_s, timing.detect_s = 5.0, {False: 0.01}  # a slow frame's mean: detection would wait about 5 s
    timing.tracking()
    threading.Timer(0.05, timing.tracked).start()
    started = time.monotonic()
    timing.wait()
    assert time.monotonic() - started < 2.0 and timing.wait_s() == 0.0


def _track_frames(timing: JustInTime, now: list[float], seconds: list[float]) -> None:
    for s in seconds:
        timing.tracking()
        now[0] += s
        timing.tracked()


def test_one_slow_frame_does_not_hold_back_the_next_detections(monkeypatch):
    """A track's start takes 0.8 s among 0.1 s frames: the next frame's detection is still due
    0.1 s less its own time after the tracker starts (a running mean would say 0.31 s)."""
    now = [100.0]
    monkeypatch.setattr(time, "monotonic", lambda: now[0])
    timing = JustInTime()
    timing.detected(0.02)
    _track_frames(timing, now, [0.1] * 5 + [0.8])
    assert timing.track_s == pytest.approx(0.1)
    timing.tracking()
    assert timing.wait_s() == pytest.approx(0.1 - 0.02)


def test_the_due_time_follows_the_tracker_when_its_frames_get_slower(monkeypatch):
    """The median of the last frames: half the recent frames slower moves the due time to them."""
    now = [100.0]
    monkeypatch.setattr(time, "monotonic", lambda: now[0])
    timing = JustInTime()
    timing.detected(0.01)
    _track_frames(timing, now, [0.1] * RECENT_FRAMES + [0.3] * (RECENT_FRAMES // 2 + 1))
    assert timing.track_s == pytest.approx(0.3)


def test_a_segmenting_detection_starts_by_its_own_time(monkeypatch):
    """Segmented detections take 0.08 s, whole-frame ones 0.02 s: with the tracker due after 0.1 s, a
    detection that will segment starts 0.02 s after the tracker does, one that will not 0.08 s after;
    before a kind is measured, the other kind's time stands in."""
    now = [100.0]
    monkeypatch.setattr(time, "monotonic", lambda: now[0])
    timing = JustInTime()
    timing.detected(0.02, segmented=False)
    _track_frames(timing, now, [0.1])
    timing.tracking()
    assert timing.wait_s(segmenting=True) == pytest.approx(0.1 - 0.02)  # no segmented one measured yet
    timing.detected(0.08, segmented=True)
    assert timing.wait_s(segmenting=True) == pytest.approx(0.1 - 0.08)
    assert timing.wait_s(segmenting=False) == pytest.approx(0.1 - 0.02)


def test_the_tracker_waits_for_a_newer_frame_only_when_it_is_due_soon(monkeypatch):
    """fresher_s against the rule worked out by hand: due within half of how much newer the frame is
    and within MAX_WAIT_S, the wait is what is left plus WAIT_SLACK_S, capped by that limit."""
    from swarmpose.pipeline.schedule import MAX_WAIT_S, WAIT_SHARE, WAIT_SLACK_S

    now = [50.0]
    monkeypatch.setattr(time, "monotonic", lambda: now[0])
    timing = JustInTime()
    held = 1_000_000_000  # the capture time (ns) of the frame the tracker is about to take
    assert timing.fresher_s(held) is None  # nothing in detection
    timing.detected(0.020)  # a whole frame's detection takes 20 ms
    timing.detecting(now[0], False, held + 33_000_000)  # the next camera frame, 33 ms newer, just taken
    now[0] += 0.017
    assert timing.fresher_s(held) == pytest.approx(0.003 + WAIT_SLACK_S)  # due in 3 ms: wait for it
    now[0] -= 0.015
    assert timing.fresher_s(held) is None  # due in 18 ms, more than half of 33 ms: not worth it
    now[0] += 0.015
    assert timing.fresher_s(held + 33_000_000) is None  # not newer than the frame held
    timing.detecting(now[0] - 0.021, False, held + 200_000_000)  # much newer, overdue by 1 ms
    assert timing.fresher_s(held) == pytest.approx(min(WAIT_SLACK_S, WAIT_SHARE * 0.2, MAX_WAIT_S))
    timing.detecting(now[0], True, held + 200_000_000)  # a segmented frame, no segmented time known yet:
    assert timing.fresher_s(held) == pytest.approx(MAX_WAIT_S)  # the whole frames' 20 ms, +5 capped at 25
    timing.detected(0.060, True)
    assert timing.fresher_s(held) is None  # done: nothing in detection any more
    timing.detecting(now[0], True, held + 200_000_000)
    assert timing.fresher_s(held) is None  # a segmented frame takes 60 ms: longer than anyone waits
