"""The offline backward pass (``backward`` setting, :mod:`swarmpose.pipeline.backward`): against
the sequence's ground truth, against a backward run made by hand with the tracker itself, with
several people, and on stops, errors and settings it cannot serve."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest
from conftest import people_scores

import swarmpose
from swarmpose.body.loader import load_body
from swarmpose.cli.main import main
from swarmpose.core.errors import ConfigError
from swarmpose.detect.registry import make_detector
from swarmpose.pipeline.backward import SETTLED_AGE, BackwardPass, StepInput, person_steps
from swarmpose.pipeline.run import RunSummary, results, run_sequence
from swarmpose.pipeline.step import FramePipeline
from swarmpose.sources.base import Frame
from swarmpose.sources.groundtruth import load_ground_truth
from swarmpose.sources.registry import open_source
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.config import TrackerConfig
from swarmpose.tracking.result import BodyResult, FrameResult

SMALL = {"particles": 24, "generations": 24, "max_people": 1, "auto_height": False}


def _errors_mm(folder: Path, run) -> np.ndarray:
    """Per frame, the mean 3D joint error (mm) of the first body against the ground truth."""
    gt = load_ground_truth(folder)
    return np.array([1000 * np.linalg.norm(r.bodies[0].joints3d - gt.joints3d[gt.row(r.index)], axis=1).mean()
                     for r in run])


@pytest.mark.slow
def test_the_backward_pass_removes_the_starts_settling_from_a_side_view(side_wave):
    forward = list(swarmpose.track(f"folder:{side_wave}", detector="simulated", **SMALL))
    both = list(swarmpose.track(f"folder:{side_wave}", detector="simulated", backward=20, **SMALL))
    assert [r.index for r in both] == list(range(20)) and all(r.bodies[0].state != "lost" for r in both)
    ahead, behind = _errors_mm(side_wave, forward), _errors_mm(side_wave, both)
    # measured: the forward track's first five frames 80.7 mm, its last five 53.3; backward 54.1
    assert behind[:5].mean() <= ahead[:5].mean() - 10, (ahead[:5].mean(), behind[:5].mean())
    assert behind[:5].mean() <= behind[-5:].mean() + 10
    assert behind[-1] == ahead[-1]  # the window's last frame is the backward pass's start, kept as it was


@pytest.mark.slow
def test_each_window_is_the_tracker_run_backwards_from_the_windows_last_solution(side_wave):
    """A backward pass made by hand with a BodyTracker on the source's frames and the forward
    run's detections gives each frame's refit pose exactly."""
    settings = {**SMALL, "particles": 12, "generations": 8}
    frames = 11
    forward = list(swarmpose.track(f"folder:{side_wave}", detector="simulated", frames=frames, **settings))
    both = list(swarmpose.track(f"folder:{side_wave}", detector="simulated", frames=frames, backward=4, **settings))
    assert [r.index for r in both] == list(range(frames))
    config = TrackerConfig(**settings)
    source = open_source(f"folder:{side_wave}")
    seen = [f for f in source if isinstance(f, Frame)][:frames]
    source.close()
    body = load_body("builtin")
    body = body if len(body.triangles) <= config.triangles else body.tracking_lod(config.triangles)
    tracker = BodyTracker(body, seen[0].intrinsics, config)
    for first, last in ((0, 3), (4, 7), (8, 10)):  # windows of 4 frames, the last one short
        assert np.array_equal(both[last].bodies[0].pose, forward[last].bodies[0].pose)
        tracker.reset()
        start = forward[last].bodies[0].pose
        tracker.previous, tracker.age = start.copy(), SETTLED_AGE
        tracker.history.restart(start.copy())
        for k in range(last - 1, first - 1, -1):
            mine = tracker.step(seen[k], forward[k].bodies[0].detection)
            assert np.allclose(both[k].bodies[0].pose, mine.pose, atol=1e-9), k
            assert "backward" in both[k].timings_ms


@pytest.mark.slow
def test_with_several_people_each_id_is_refit_on_its_own_frames(two_people):
    settings = {"particles": 16, "generations": 12, "max_people": 3, "auto_height": False, "frames": 6}
    forward = list(swarmpose.track(f"folder:{two_people}", detector="simulated", **settings))
    both = list(swarmpose.track(f"folder:{two_people}", detector="simulated", backward=6, **settings))
    assert [[b.id for b in r.bodies] for r in both] == [[b.id for b in r.bodies] for r in forward]
    refit = [not np.array_equal(a.pose, b.pose) for r, s in zip(forward[:-1], both[:-1])
             for a, b in zip(r.bodies, s.bodies)]
    assert sum(refit) >= len(refit) - 1  # every person's earlier frames were refit
    scores = people_scores(two_people, both)
    assert scores["id_switches"] == 0 and scores["misses"] == 0
    assert all(s["mpjpe_mm"] < 120 for s in scores["per_person"].values())


def test_a_stopped_run_hands_on_the_frames_it_held(wave_sequence):
    """A stop (SIGINT) ends the reading; the frames waiting for their backward pass reach the sinks
    at once, as the forward pass left them."""
    stop = threading.Event()
    source = open_source(f"folder:{wave_sequence}")

    def stopping():
        for item in source:
            if item.index == 2:  # as a signal during frame 2's tracking
                stop.set()
            yield item

    got = []

    class Keep:
        def frame(self, message, frame):
            got.append(message)

        def close(self):
            pass

    config = TrackerConfig(particles=12, generations=8, max_people=1, backward=10)
    pipeline = FramePipeline(make_detector("simulated", source),
                             lambda intr, body_id: BodyTracker(load_body("builtin"), intr, config, body_id=body_id),
                             max_people=1, backward=config.backward)
    summary = run_sequence(stopping(), pipeline, [Keep()], progress=False, stop=stop)
    source.close()
    assert [m["frame"] for m in got] == [0, 1, 2] and summary.interrupted and summary.frames == 3
    assert all("backward" not in m["timings_ms"] for m in got)  # promptly: with their forward fits


@pytest.mark.slow
@pytest.mark.parametrize("offline", [{"backward": 10}, {"smoothing": "centred"},
                                     {"backward": 10, "smoothing": "centred"}])
def test_a_source_that_breaks_hands_on_the_frames_held_as_found_then_raises(wave_sequence, offline):
    """The backward pass and the centred smoothing (``test_centred_smoothing.py``) hold frames; a source
    that breaks gets them handed on as the forward pass found them, then its error."""
    source = open_source(f"folder:{wave_sequence}")

    def breaking():
        for item in source:
            if item.index == 3:
                raise OSError("the recording is truncated")
            yield item

    config = TrackerConfig(particles=12, generations=8, max_people=1, **offline)
    pipeline = FramePipeline(make_detector("simulated", source),
                             lambda intr, body_id: BodyTracker(load_body("builtin"), intr, config, body_id=body_id),
                             max_people=1, backward=config.backward, centred_sigma_s=config.centred_sigma_s)
    got, summary = [], RunSummary()
    with pytest.raises(OSError, match="truncated"):
        for result in results(breaking(), pipeline, summary=summary):
            got.append(result)
    source.close()
    assert [r.index for r in got] == [0, 1, 2] and summary.frames == 3
    assert all("backward" not in r.timings_ms and r.bodies[0].unfiltered is None for r in got)


@pytest.mark.parametrize("settings, words", [
    ({"backward": 5, "mode": "lift"}, "lift mode fits none"),
    ({"backward": 5, "smoothing": "one-euro"}, "choose one"),
    ({"ensemble": 3, "mode": "lift"}, "no search"),
    ({"ensemble": 3, "backward": 5}, "choose one"),
])
def test_settings_the_backward_pass_or_an_ensemble_cannot_serve_are_refused(settings, words):
    with pytest.raises(ConfigError, match=words):
        TrackerConfig(**settings)


def test_replay_and_the_frame_by_frame_tracker_refuse_it_and_name_what_to_run(wave_sequence, tmp_path, capsys,
                                                                              monkeypatch):
    with pytest.raises(SystemExit) as exit_:  # not offered as a flag
        main(["replay", str(wave_sequence), "--out", str(tmp_path), "--backward", "5", "-q"])
    assert exit_.value.code == 2 and "unrecognized arguments: --backward" in capsys.readouterr().err
    monkeypatch.setenv("SWARMPOSE_BACKWARD", "5")  # asked for another way
    assert main(["replay", str(wave_sequence), "--out", str(tmp_path), "-q"]) == 2
    err = capsys.readouterr().err
    assert "backward = 5: not in serve and replay" in err and "swarmpose track" in err
    monkeypatch.delenv("SWARMPOSE_BACKWARD")
    source = open_source(f"folder:{wave_sequence}")
    with swarmpose.Tracker("builtin", "simulated", source=source, backward=5) as tracker:
        with pytest.raises(ConfigError, match="swarmpose.track"):
            tracker.track_frame(next(iter(source)))
    source.close()


def test_a_window_of_no_frames_is_refused():
    with pytest.raises(ValueError, match="at least 1"):
        BackwardPass(0)


def _step(frame_index: int, body_id: int, note: str) -> StepInput:
    frame = Frame(frame_index, 0, np.zeros((2, 2), np.float32), None, None)
    return StepInput(body_id, None, None, None, frame, note, False)


def _frame_with(index: int, *ids: int) -> FrameResult:
    bodies = tuple(BodyResult(i, "tracking", "", np.zeros(36), np.zeros((14, 3)), np.zeros((14, 2)), np.zeros(14))
                   for i in ids)
    return FrameResult(index, 0, bodies)


def test_each_id_is_refit_on_the_steps_whose_fit_it_published():
    """A new person's tracker is tried under the next id on each unexplained segment and let go when
    it finds nobody: those steps carry an id they never published (frame 0, id 2), or come before
    the step that gave the id its fit in the same frame (frame 1, id 2: the larger segment is tried
    first). Only the last step of an id in a frame it published is refit."""
    steps = [_step(0, 1, "person 1"), _step(0, 2, "nobody"),
             _step(1, 1, "person 1"), _step(1, 2, "a larger segment, nobody"), _step(1, 2, "person 2"),
             _step(2, 1, "person 1"), _step(2, 2, "person 2"), _step(2, 3, "nobody")]
    held = [_frame_with(0, 1), _frame_with(1, 1, 2), _frame_with(2, 1, 2)]
    chosen = person_steps(steps, held)
    assert {k: [(s.frame.index, s.joints) for s in v] for k, v in chosen.items()} == {
        1: [(0, "person 1"), (1, "person 1"), (2, "person 1")], 2: [(1, "person 2"), (2, "person 2")]}


def test_a_step_keeps_the_body_its_tracker_had_then(wave_sequence):
    """A retired person's tracker goes back to its start body (``new_person``) before the window's
    backward pass: the step recorded the scaled body the person was tracked with."""
    from swarmpose.personalise.auto_height import height_fitting_tracker, scaled_body

    source = open_source(f"folder:{wave_sequence}")
    frame = next(iter(source))
    source.close()
    tracker = height_fitting_tracker(load_body("builtin"), frame.intrinsics, TrackerConfig(particles=8, generations=4))
    fitting = tracker.fitting
    fitting.factor = 1.1  # as its height measure does
    tracker.set_body(scaled_body(fitting.given_body, fitting.factor))
    held = BackwardPass(5)
    held.record(tracker, frame, None, False)
    tracked_with = tracker.body
    tracker.new_person()
    assert tracker.body is fitting.given_body and held.steps[0].body is tracked_with
    assert held.steps[0].body.height == pytest.approx(1.1 * fitting.given_body.height, rel=1e-6)


@pytest.mark.slow
def test_a_person_whose_backward_run_fails_keeps_the_forward_fits_and_it_is_logged(wave_sequence, caplog):
    from dataclasses import replace

    source = open_source(f"folder:{wave_sequence}")
    config = TrackerConfig(particles=12, generations=8, max_people=1, backward=3)
    pipeline = FramePipeline(make_detector("simulated", source),
                             lambda intr, body_id: BodyTracker(load_body("builtin"), intr, config, body_id=body_id),
                             max_people=1, backward=config.backward)
    held = BackwardPass(config.backward)
    pipeline.on_step = held.record
    forward = [pipeline.process(item) for item, _ in zip(source, range(3))]
    source.close()
    for result in forward:
        held.results.append(result)
    broken = held.steps[0].frame
    held.steps[0] = replace(held.steps[0], frame=replace(broken, depth=broken.depth[:-1]))  # a row short
    with caplog.at_level("WARNING", logger="swarmpose"):
        out = held.flush()
    assert [r.index for r in out] == [0, 1, 2]
    assert all(np.array_equal(a.bodies[0].pose, b.bodies[0].pose) for a, b in zip(out, forward))
    assert "backward pass of person 0 over frames 0-2 failed" in caplog.text
