"""The worker: hand-overs, replay and live policies, failures that must not stop it, status, health.

Real parts throughout (folder source on a synthetic sequence, the simulated detector, the
tracker); failures are injected by wrapping a real part so that it fails the way a broken
camera, detector or frame would.
"""

from __future__ import annotations

import json
import re
import signal
import threading
import time
from contextlib import ExitStack
from dataclasses import replace

import numpy as np
import pytest

from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.cli.common import stop_on_signals
from swarmpose.cli.main import main
from swarmpose.core.errors import DetectorError, OutputError, SourceError
from swarmpose.detect.registry import make_detector
from swarmpose.messages import validate
from swarmpose.pipeline.handover import END, Handover
from swarmpose.pipeline.status import HealthFileSink, write_health_file
from swarmpose.pipeline.step import FramePipeline
from swarmpose.pipeline.worker import Worker
from swarmpose.publish.files import JsonlSink
from swarmpose.sources.base import FrameSource
from swarmpose.sources.groundtruth import load_ground_truth
from swarmpose.sources.registry import open_source
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.config import TrackerConfig

LIFT = TrackerConfig(mode="lift")
SMALL = TrackerConfig(particles=12, generations=8)


class Collect:
    """A sink that keeps what it is given."""

    def __init__(self):
        self.frames, self.statuses, self.closed = [], [], 0

    def frame(self, message, frame):
        self.frames.append(message)

    def status(self, message):
        self.statuses.append(message)

    def close(self):
        self.closed += 1


@pytest.fixture(scope="module")
def body():
    return load_body("builtin")


def make_worker(sequence, body, sinks, config=LIFT, *, drop_stale=False, source=None, detector=None, **kw):
    uri = f"folder:{sequence}"
    source = source or open_source(uri)
    detector = detector or make_detector("simulated", source)
    pipeline = FramePipeline(detector, lambda intr, _id: BodyTracker(body, intr, config), max_people=1)
    return Worker(lambda: open_source(uri), pipeline, sinks,
                  camera="test", drop_stale=drop_stale, source_uri=uri, detector_spec="simulated",
                  status_period_s=kw.pop("status_period_s", 0.2), source=source, **kw)


# ---------------------------------------------------------------------------------------------- hand-over
def test_handover_drops_the_waiting_item_when_live():
    slot = Handover(drop_stale=True)
    assert slot.put(1) is True and slot.put(2) is False and slot.put(3) is False
    assert slot.get() == 3
    slot.put(4)
    slot.finish()
    assert slot.get() == 4 and slot.get() is END


def test_handover_makes_the_producer_wait_in_replay():
    slot = Handover(drop_stale=False)
    slot.put(1)
    done = threading.Event()
    threading.Thread(target=lambda: (slot.put(2), done.set()), daemon=True).start()
    assert not done.wait(0.2)          # the second put waits for the consumer
    assert slot.get() == 1
    assert done.wait(2) and slot.get() == 2
    slot.abort()
    assert slot.get() is END


# ---------------------------------------------------------------------------------------------- pipelines
def test_replay_publishes_every_frame_in_order_with_valid_messages(wave_sequence, body):
    sink = Collect()
    stats = make_worker(wave_sequence, body, [sink]).run()
    assert [m["frame"] for m in sink.frames] == list(range(6))
    for m in sink.frames:
        validate(m)
        assert m["bodies"][0]["state"] == "tracking" and m["latency_ms"] >= 0
    truth = load_ground_truth(wave_sequence).joints3d
    est = np.array([[m["bodies"][0]["joints"][j]["position_m"] or [np.nan] * 3 for j in EVAL_JOINTS]
                    for m in sink.frames])
    assert np.nanmean(np.linalg.norm(est - truth, axis=2)) < 0.08   # J^e lifted from the simulated detections
    assert (stats.received, stats.published, stats.dropped, stats.skipped, stats.failed) == (6, 6, 0, 0, 0)
    last = sink.statuses[-1]
    validate(last)
    assert last["state"] == "source-ended" and last["frames"]["published"] == 6 and sink.closed == 1


@pytest.mark.slow
def test_replay_latency_is_the_processing_time_not_the_queue(wave_sequence, body):
    """Frames queue behind each other in replay; the latency leaves that out (tracking time + detection)."""
    sink = Collect()
    make_worker(wave_sequence, body, [sink], SMALL).run()
    for m in sink.frames[1:]:
        tracking = m["timings_ms"]["total"]
        assert tracking <= m["latency_ms"] < 1.5 * tracking + 100, (m["frame"], tracking, m["latency_ms"])


def test_live_keeps_the_newest_frame_and_counts_the_dropped(wave_sequence, body):
    sink = Collect()
    stats = make_worker(wave_sequence, body, [sink], SMALL, drop_stale=True, pace_fps=200.0).run()
    frames = [m["frame"] for m in sink.frames]
    assert frames == sorted(frames) and frames[-1] == 5    # in order, and the newest frame is always tracked
    assert stats.dropped > 0 and stats.published + stats.dropped == stats.received == 6
    assert sink.statuses[-1]["frames"]["dropped"] == stats.dropped
    assert sink.statuses[-1]["opencl_device"]                 # the scorer's device is reported


def test_live_reads_only_the_frames_it_tracks(wave_sequence, body, monkeypatch):
    """Served at its rate, a folder's frames are decoded when detection takes them, not when they are
    dropped on the way there: fewer depth images read than frames served, at least one per published;
    the published frames carry the source's own numbers, in order (which ones survive the pacing
    depends on the machine's load: under load even frame 0 can be dropped)."""
    import swarmpose.sources.folder as folder

    reads = []
    real = folder.read_depth
    monkeypatch.setattr(folder, "read_depth", lambda path, units: reads.append(path) or real(path, units))
    sink = Collect()
    stats = make_worker(wave_sequence, body, [sink], SMALL, drop_stale=True, pace_fps=200.0).run()
    assert stats.dropped > 0 and stats.published <= len(reads) < stats.received
    numbers = [frame.index for frame in open_source(f"folder:{wave_sequence}")]
    published = [m["frame"] for m in sink.frames]
    assert published == sorted(set(published)) and set(published) <= set(numbers), (published, numbers)


class FlakyDetector:
    """The real detector, failing on chosen frames as a crashing network would."""

    def __init__(self, inner, fail_on):
        self.inner, self.fail_on = inner, set(fail_on)

    def detect(self, frame, box=None):
        if frame.index in self.fail_on:
            raise RuntimeError("onnxruntime: CUDA out of memory")
        return self.inner.detect(frame, box)

    def close(self):
        self.inner.close()


@pytest.mark.slow
def test_a_detector_that_throws_is_reported_and_the_frame_still_tracked(wave_sequence, body):
    source = open_source(f"folder:{wave_sequence}")
    detector = FlakyDetector(make_detector("simulated", source), {2})
    sink = Collect()
    stats = make_worker(wave_sequence, body, [sink], SMALL, source=source, detector=detector).run()
    assert [m["frame"] for m in sink.frames] == list(range(6))
    hit = sink.frames[2]
    assert "detector failed: CUDA out of memory" in hit["reason"].replace("onnxruntime: ", "")
    assert hit["bodies"] and hit["bodies"][0]["pose"] is not None     # tracked on depth from the previous pose
    assert stats.detector_errors == 1 and stats.failed == 1
    status = sink.statuses[-1]
    assert status["detector"]["errors"] == 1 and "CUDA out of memory" in status["detector"]["last_error"]


class BadFrameSource(FrameSource):
    """The real folder source, with frame ``bad`` cropped to a size the tracker cannot use."""

    def __init__(self, inner, bad):
        self.inner, self.bad, self.uri, self.length = inner, bad, inner.uri, inner.length

    def _frames(self):
        for item in self.inner:
            if getattr(item, "index", None) == self.bad:
                item = replace(item, depth=item.depth[:100, :100])
            yield item


def test_a_frame_that_fails_to_track_is_published_empty_and_the_track_restarts(wave_sequence, body):
    inner = open_source(f"folder:{wave_sequence}")
    source = BadFrameSource(inner, 3)
    sink = Collect()
    make_worker(wave_sequence, body, [sink], LIFT, source=source, detector=make_detector("simulated", inner)).run()
    assert [m["frame"] for m in sink.frames] == list(range(6))
    bad = sink.frames[3]
    assert bad["bodies"] == [] and bad["reason"].startswith("tracking failed") and "100x100" in bad["reason"]
    assert sink.frames[4]["bodies"][0]["state"] == "tracking"
    assert sink.statuses[-1]["tracker"]["failures"] == 1 and sink.statuses[-1]["frames"]["failed"] == 1


class DyingSource(FrameSource):
    """The real folder source, whose device 'vanishes' after ``keep`` frames."""

    def __init__(self, inner, keep, live=False):
        self.inner, self.keep, self.live, self.uri = inner, keep, live, inner.uri

    def _frames(self):
        for i, item in enumerate(self.inner):
            if i == self.keep:
                raise SourceError("USB device disconnected")
            yield item


def test_a_recording_that_dies_ends_the_run_keeping_every_line(wave_sequence, body, tmp_path):
    inner = open_source(f"folder:{wave_sequence}")
    jsonl = JsonlSink(tmp_path / "poses.jsonl")
    sink = Collect()
    worker = make_worker(wave_sequence, body, [sink, jsonl], source=DyingSource(inner, 3),
                         detector=make_detector("simulated", inner))
    worker.run()
    lines = [json.loads(x) for x in (tmp_path / "poses.jsonl").read_text().splitlines()]
    assert [x["frame"] for x in lines] == [0, 1, 2]
    status = sink.statuses[-1]
    assert status["state"] == "source-failed" and "USB device disconnected" in status["source"]["state"]
    assert any("USB device disconnected" in e for e in status["errors"])


def test_a_live_source_that_dies_is_reopened(wave_sequence, body):
    inner = open_source(f"folder:{wave_sequence}")
    sink = Collect()
    worker = make_worker(wave_sequence, body, [sink], source=DyingSource(inner, 2, live=True),
                         detector=make_detector("simulated", inner), reopen_s=0.1)
    worker.run()
    frames = [m["frame"] for m in sink.frames]
    assert frames == [0, 1] + list(range(6))          # the reopened source delivers from its start again
    assert any("reopening in 0.1 s" in e for e in sink.statuses[-1]["errors"])


class BrokenSink(Collect):
    """Fails on its first frame; records the order of the calls it gets."""

    def __init__(self):
        super().__init__()
        self.calls, self.order = 0, []

    def frame(self, message, frame):
        self.calls += 1
        self.order.append("frame")
        raise OutputError("disk full writing /data/poses.csv")

    def status(self, message):
        super().status(message)
        self.order.append("status")


def test_a_failing_sink_is_reported_once_dropped_and_the_others_go_on(wave_sequence, body):
    good, broken = Collect(), BrokenSink()
    worker = make_worker(wave_sequence, body, [broken, good])
    worker.run()
    assert len(good.frames) == 6
    # dropped after its failing frame, still closed; a status may reach it before that frame (the worker
    # sends one every status period, and a loaded machine takes longer than that to its first frame)
    assert broken.calls == 1 and broken.order[-1] == "frame" and broken.closed == 1
    assert worker.sink_errors == ["BrokenSink: disk full writing /data/poses.csv"]
    assert sum("disk full" in e for e in good.statuses[-1]["errors"]) == 1
    assert good.statuses[-1]["state"] == "source-ended"


@pytest.mark.slow
def test_stop_ends_a_running_worker_promptly(wave_sequence, body):
    sink = Collect()
    worker = make_worker(wave_sequence, body, [sink], SMALL, drop_stale=True, pace_fps=2.0, loop=True)
    threading.Timer(1.5, worker.stop).start()
    t0 = time.monotonic()
    worker.run()
    assert time.monotonic() - t0 < 20
    assert sink.statuses[-1]["state"] == "stopping" and sink.closed == 1


def test_a_signal_while_the_main_thread_holds_the_lock_stops_at_once(wave_sequence, body):
    """The CLI's SIGTERM handler runs in the main thread, maybe while it holds the worker's lock."""
    worker = make_worker(wave_sequence, body, [Collect()])
    safety = threading.Timer(5.0, worker._lock.release)   # would unblock a deadlocked stop()
    with ExitStack() as stack:
        stop_on_signals(worker.stop, stack)
        worker._lock.acquire()
        safety.start()
        t0 = time.monotonic()
        signal.raise_signal(signal.SIGTERM)
        waited = time.monotonic() - t0
        safety.cancel()
        if worker._lock.locked():
            worker._lock.release()
    worker.source.close()
    assert waited < 1.0 and worker.state == "stopping"
    worker._set_state("running")
    assert worker.state == "stopping"        # a stop is final


# ---------------------------------------------------------------------------------------------- health
def test_health_reads_the_status_file(wave_sequence, body, tmp_path, capsys):
    health = tmp_path / "status.json"
    make_worker(wave_sequence, body, [HealthFileSink(health)]).run()
    status = json.loads(health.read_text())
    validate(status)
    assert main(["health", "--file", str(health)]) == 1
    assert "worker state source-ended" in capsys.readouterr().out
    write_health_file(str(health), {**status, "state": "running", "time_ns": time.time_ns()})
    assert main(["health", "--file", str(health)]) == 0
    write_health_file(str(health), {**status, "state": "running", "time_ns": time.time_ns() - int(60e9)})
    assert main(["health", "--file", str(health), "--max-age", "15"]) == 1
    age = re.search(r"last status ([0-9.]+) s old", capsys.readouterr().out.splitlines()[-1])
    assert age and 60.0 <= float(age.group(1)) < 70.0  # 60 s, plus however long the command took to start
    assert main(["health", "--file", str(tmp_path / "none.json")]) == 1
    out = capsys.readouterr().out
    assert "no status" in out and "--health-file" in out
    assert main(["health", "--file", str(tmp_path / "missing" / "status.json")]) == 1  # a path nobody can write
    assert "its folder does not exist" in capsys.readouterr().out


def test_a_detector_error_type_from_the_project_is_reported_the_same(wave_sequence, body):
    source = open_source(f"folder:{wave_sequence}")

    class Refusing(FlakyDetector):
        def detect(self, frame, box=None):
            raise DetectorError("model.onnx: input has 4 channels, expected 3")

    sink = Collect()
    make_worker(wave_sequence, body, [sink], source=source,
                detector=Refusing(make_detector("simulated", source), set())).run()
    assert all("expected 3" in m["reason"] for m in sink.frames)
    assert all(m["bodies"][0]["state"] == "lost" for m in sink.frames)   # lift mode: no joints, no answer


def test_serving_a_recording_without_a_rate_warns_and_assumes_30_fps_and_its_budget(wave_sequence, tmp_path, caplog):
    import json
    import shutil
    from contextlib import ExitStack
    from dataclasses import replace

    from swarmpose.pipeline.config import ServiceConfig, ZenohConfig
    from swarmpose.pipeline.service import build_worker
    from swarmpose.tracking.config import TrackerConfig

    bare = tmp_path / "bare"
    shutil.copytree(wave_sequence, bare)
    meta = json.loads((bare / "sequence.json").read_text())
    del meta["fps"]
    (bare / "sequence.json").write_text(json.dumps(meta))
    for folder, warned in ((wave_sequence, False), (bare, True)):
        caplog.clear()
        config = ServiceConfig(source=str(folder), detector="simulated", overlay=False,
                               zenoh=ZenohConfig(zenoh_mode="off"), tracker=TrackerConfig(mode="lift", max_people=1))
        with ExitStack() as stack:
            worker, parts, _ = build_worker(config, stack, replay=False)
            assert worker.pace_fps == 30.0 and parts.pipeline.frame_period_s == 1 / 30
            assert parts.pipeline.budget_ms == pytest.approx(30.0), "auto: 0.9 of the 33.3 ms period"
        assert ("records no frame rate" in caplog.text) == warned
    with ExitStack() as stack:
        _, parts, _ = build_worker(replace(config, frame_budget_ms=45.0), stack, replay=False)
        assert parts.pipeline.budget_ms == 45.0
    with ExitStack() as stack:  # served at 10 frames/s: 0.9 of the 100 ms between the frames that come
        _, parts, _ = build_worker(replace(config, rate=10.0), stack, replay=False)
        assert parts.pipeline.budget_ms == pytest.approx(90.0) and parts.pipeline.frame_period_s == 1 / 30


@pytest.mark.slow
def test_a_looped_recording_starts_its_tracks_afresh(wave_sequence, body):
    """Each pass over a looped recording is a new take: its first frame starts a new track (state
    init), not a continuation of the last frame's, where the person was somewhere else."""
    sink = Collect()
    make_worker(wave_sequence, body, [sink], SMALL, loop=True, frames=12).run()
    states = [(m["frame"], m["bodies"][0]["state"]) for m in sink.frames]
    assert [s for f, s in states if f == 0] == ["init", "init"]
    assert all(s == "tracking" for f, s in states if f != 0)


def test_handover_get_gives_up_after_its_timeout():
    slot = Handover(drop_stale=True)
    started = time.monotonic()
    assert slot.get(timeout=0.05) is None and time.monotonic() - started >= 0.05
    threading.Timer(0.02, slot.put, (7,)).start()
    assert slot.get(timeout=2.0) == 7  # an item that comes within the timeout
    slot.put(8)
    assert slot.get(timeout=0.0) == 8  # one waiting already: no wait at all
    slot.finish()
    assert slot.get(timeout=0.05) is END


def test_live_detection_holds_an_early_frame_until_due_and_takes_a_newer_one_then(wave_sequence, body):
    """A frame that came before detection is due gives way to one that came by then (counted as
    dropped); without a newer one it is detected as it is."""
    from swarmpose.pipeline.worker import Received

    worker = make_worker(wave_sequence, body, [Collect()], drop_stale=True)
    timing = worker._timing
    timing.track_s, timing.detect_s = 0.08, {False: 0.02}
    early, newer = Received("early", 1), Received("newer", 2)
    started = time.monotonic()
    timing.tracking()  # the tracker just took a frame: detection is due in 60 ms
    worker._acquired.put(newer)  # a newer frame comes meanwhile
    assert worker._newest_when_due(early, False) is newer
    assert time.monotonic() - started >= 0.06 - 1e-3 and worker.stats.dropped == 1
    timing.tracking()
    assert worker._newest_when_due(early, False) is early and worker.stats.dropped == 1
    timing.tracked()  # the tracker is idle: a frame is taken at once, without looking for another
    worker._acquired.put(newer)
    assert worker._newest_when_due(early, False) is early and worker._acquired.get(timeout=0.0) is newer


def test_the_live_tracker_waits_for_a_newer_frame_about_to_be_detected(wave_sequence, body):
    from swarmpose.pipeline.worker import Received

    worker = make_worker(wave_sequence, body, [Collect()], drop_stale=True)
    timing = worker._timing
    timing.detect_s = {False: 0.02}
    held, newer = Received("held", 1_000_000_000), Received("newer", 1_033_000_000)
    timing.detecting(time.monotonic() - 0.015, False, newer.received_ns)  # due in 5 ms
    worker._detected.put(newer)
    assert worker._fresher(held) is newer and worker.stats.dropped == 1
    timing.detecting(time.monotonic(), False, newer.received_ns)  # due in 20 ms: more than half of 33 ms
    worker._detected.put(newer)
    assert worker._fresher(held) is held and worker._detected.get(timeout=0.0) is newer  # not even looked at


class CallRecorder:
    """The real detector, noting its calls in order: ("detect", frame index) and "reset"."""

    def __init__(self, inner):
        self.inner, self.calls = inner, []

    def detect(self, frame, box=None):
        self.calls.append(("detect", frame.index))
        return self.inner.detect(frame, box)

    def reset(self):
        self.calls.append("reset")

    def close(self):
        self.inner.close()


def test_a_looped_recording_resets_its_detector_before_the_first_frame_of_each_new_pass(wave_sequence, body):
    """The detection thread, which runs ahead of the tracker, resets the detector itself when a new take
    begins, once and before detecting its first frame (so a frame of the new take is never cropped from
    the old take's regions, and regions found on the new take are not thrown away by a late reset)."""
    source = open_source(f"folder:{wave_sequence}")
    detector = CallRecorder(make_detector("simulated", source))
    frames = len(load_ground_truth(wave_sequence).joints3d)
    make_worker(wave_sequence, body, [Collect()], source=source, detector=detector, loop=True,
                frames=2 * frames).run()
    first_pass = [("detect", k) for k in range(frames)]
    assert detector.calls == first_pass + ["reset"] + first_pass
