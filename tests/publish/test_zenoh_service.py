"""The worker on zenoh: real sessions on 127.0.0.1 with multicast scouting off.

A plain zenoh subscriber (zenoh's own API, not swarmpose.publish.client) receives the frames and
validates them with jsonschema against the files in protocol/; liveliness appears while the
worker runs and disappears after; the info queryable answers; the client API; endpoints that
are malformed or unreachable.
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import jsonschema
import pytest
import zenoh
from conftest import REPO, free_port

from swarmpose.body.loader import load_body
from swarmpose.core.errors import PublishError
from swarmpose.core.polling import wait_until
from swarmpose.detect.registry import make_detector
from swarmpose.pipeline.status import HealthFileSink
from swarmpose.pipeline.step import FramePipeline
from swarmpose.pipeline.worker import Worker
from swarmpose.publish.client import Client
from swarmpose.publish.zenoh_link import ZenohSink
from swarmpose.sources.registry import open_source
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.config import TrackerConfig

SCHEMAS = {name: json.loads((REPO / "protocol" / f"{name}.schema.json").read_text())
           for name in ("frame", "status", "info")}


def plain_session(connect: str | None = None, listen: str | None = None, mode: str = "peer") -> zenoh.Session:
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    config.insert_json5("scouting/multicast/enabled", "false")
    if connect:
        config.insert_json5("connect/endpoints", json.dumps([connect]))
    if listen:
        config.insert_json5("listen/endpoints", json.dumps([listen]))
    return zenoh.open(config)



@pytest.fixture(scope="module")
def body():
    return load_body("builtin")


class HoldAtFrame:
    """A sink that blocks the worker at frame ``index`` until ``release`` is set (at most 20 s)."""

    def __init__(self, index: int, release: threading.Event):
        self.index, self.release = index, release
        self.holding = threading.Event()
        self.timed_out = False

    def frame(self, message: dict, frame) -> None:
        if message["frame"] == self.index:
            self.holding.set()
            self.timed_out = not self.release.wait(20)

    def status(self, message: dict) -> None:
        pass

    def close(self) -> None:
        pass


def worker_on(sequence, body, sink, *more_sinks, **kw) -> Worker:
    uri = f"folder:{sequence}"
    source = open_source(uri)
    pipeline = FramePipeline(make_detector("simulated", source),
                             lambda intr, _id: BodyTracker(body, intr, TrackerConfig(mode="lift")), max_people=1)
    return Worker(lambda: open_source(uri), pipeline, [sink, *more_sinks], camera="cam0",
                  drop_stale=False, source_uri=uri, detector_spec="simulated", status_period_s=0.2, source=source,
                  zenoh_state=sink.state, **kw)


def test_a_plain_zenoh_subscriber_gets_valid_frames_status_info_and_liveliness(wave_sequence, body):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    holder = {}
    sink = ZenohSink("cam0", lambda: holder["info"](), listen=[endpoint], multicast=False)
    sub = plain_session(connect=endpoint)
    frames, statuses, alive = [], [], []
    sub.declare_subscriber("swarmpose/cam0/frame", lambda s: frames.append((s.payload.to_bytes(), str(s.encoding))))
    sub.declare_subscriber("swarmpose/cam0/status", lambda s: statuses.append(json.loads(s.payload.to_bytes())))
    sub.liveliness().declare_subscriber("swarmpose/*/alive", lambda s: alive.append((str(s.key_expr), str(s.kind))),
                                        history=True)
    try:
        assert wait_until(lambda: sink.state()["peers"] == 1 and alive)
        assert alive == [("swarmpose/cam0/alive", "SampleKind.PUT")]
        from swarmpose.messages import info_message

        # The query must reach the worker while it runs: a finished worker closes its sinks and
        # withdraws the queryable (the 6 frames take well under the time a subscriber needs to
        # notice the first one, which made this test flaky). A sink after zenoh holds the worker at
        # its second frame until the query has been answered.
        answered = threading.Event()
        holder_sink = HoldAtFrame(1, answered)
        worker = worker_on(wave_sequence, body, sink, holder_sink)
        holder["info"] = lambda: info_message("cam0", intrinsics=worker.intrinsics, body=body, source=worker.source_uri)
        assert wait_until(sink.frames_subscribed)  # the subscription has reached the worker
        gate = threading.Event()
        runner = threading.Thread(target=lambda: (worker.run(), gate.set()))
        runner.start()
        assert wait_until(lambda: len(frames) >= 1)
        assert not gate.is_set() and holder_sink.holding.wait(10)
        # its intrinsics are known after the first frame
        replies = [r.ok for r in sub.get("swarmpose/cam0/info", timeout=5.0) if r.ok is not None]
        answered.set()
        runner.join(60)
        assert gate.is_set() and not holder_sink.timed_out
        assert len(replies) == 1
        info = json.loads(replies[0].payload.to_bytes())
        jsonschema.validate(info, SCHEMAS["info"])
        assert info["intrinsics"]["width"] == 640 and info["skeleton"]["joints"][0] == "pelvis"
        assert wait_until(lambda: len(frames) == 6)
        decoded = [json.loads(p) for p, _ in frames]
        for message in decoded:
            jsonschema.validate(message, SCHEMAS["frame"])
        assert [m["frame"] for m in decoded] == list(range(6))
        assert all(enc.startswith("application/json") for _, enc in frames)
        assert wait_until(lambda: statuses and statuses[-1]["state"] == "source-ended")
        for status in statuses:
            jsonschema.validate(status, SCHEMAS["status"])
        assert statuses[-1]["zenoh"]["peers"] == 1 and statuses[-1]["zenoh"]["listen"] == [endpoint]
        # the worker closed its sinks: the token is withdrawn
        assert wait_until(lambda: ("swarmpose/cam0/alive", "SampleKind.DELETE") in alive)
    finally:
        sink.close()
        sub.close()


def test_the_sink_knows_when_a_subscriber_matches_its_frames():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    sink = ZenohSink("cam3", lambda: {}, listen=[endpoint], multicast=False)
    sub = plain_session(connect=endpoint)
    try:
        assert wait_until(lambda: sink.state()["peers"] == 1)
        status_only = sub.declare_subscriber("swarmpose/cam3/status", lambda s: None)
        other_camera = sub.declare_subscriber("swarmpose/cam4/frame", lambda s: None)
        time.sleep(0.5)
        assert not sink.frames_subscribed()
        frames = sub.declare_subscriber("swarmpose/*/frame", lambda s: None)
        assert wait_until(sink.frames_subscribed)
        frames.undeclare()
        assert wait_until(lambda: not sink.frames_subscribed())
        status_only.undeclare()
        other_camera.undeclare()
    finally:
        sub.close()
        sink.close()
    assert not sink.frames_subscribed()


def test_an_info_query_being_answered_when_the_sink_closes_gets_its_reply():
    """A worker that ends closes its sink: a query already in the info callback is answered
    before the session goes (it used to find the session closed under it and get nothing)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    answering, proceed = threading.Event(), threading.Event()

    def slow_info() -> dict:
        answering.set()
        proceed.wait(10)
        return {"schema": "swarmpose.info", "camera": "cam0"}

    sink = ZenohSink("cam0", slow_info, listen=[endpoint], multicast=False)
    sub = plain_session(connect=endpoint)
    try:
        assert wait_until(lambda: sink.state()["peers"] == 1)
        replies = []
        query = threading.Thread(target=lambda: replies.extend(sub.get("swarmpose/cam0/info", timeout=10.0)))
        query.start()
        assert answering.wait(10)
        closer = threading.Thread(target=sink.close)
        closer.start()
        closer.join(0.5)
        assert closer.is_alive()                    # close waits for the answer in progress
        proceed.set()
        closer.join(10)
        query.join(15)
        assert [json.loads(r.ok.payload.to_bytes()) for r in replies if r.ok is not None] == [
            {"schema": "swarmpose.info", "camera": "cam0"}]
        assert sink.error == ""
    finally:
        proceed.set()
        sink.close()
        sub.close()


def test_an_info_message_that_cannot_be_made_gets_an_error_reply_naming_it():
    endpoint = f"tcp/127.0.0.1:{free_port()}"

    def broken_info() -> dict:
        raise ValueError("no intrinsics file")

    sink = ZenohSink("cam0", broken_info, listen=[endpoint], multicast=False)
    sub = plain_session(connect=endpoint)
    try:
        assert wait_until(lambda: sink.state()["peers"] == 1)
        replies = list(sub.get("swarmpose/cam0/info", timeout=10.0))
        errors = [r.err.payload.to_string() for r in replies if r.err is not None]
        assert [r for r in replies if r.ok is not None] == []
        assert errors == ["camera cam0: info query failed: no intrinsics file"]
        assert sink.error == "info query failed: no intrinsics file"
    finally:
        sink.close()
        sub.close()


def test_the_client_api_delivers_by_iterator_and_callback(wave_sequence, body):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    sink = ZenohSink("cam0", lambda: {"schema": "swarmpose.info"}, listen=[endpoint], multicast=False)
    try:
        with Client("cam0", connect=[endpoint], multicast=False) as client:
            got = []
            client.on_frame(got.append)
            assert wait_until(lambda: sink.state()["peers"] == 1)
            assert client.alive() == ["cam0"]
            # a worker answering with an invalid info message is rejected, not passed on
            assert client.info(timeout=2.0) == [] and client.rejected == 1 and "swarmpose.info" in client.last_error
            assert wait_until(sink.frames_subscribed)
            runner = threading.Thread(target=worker_on(wave_sequence, body, sink).run)
            runner.start()
            frames = list(client.frames(timeout=30, count=6))
            runner.join(60)
            assert [f["frame"] for f in frames] == list(range(6)) and wait_until(lambda: len(got) == 6)
            assert client.rejected == 1
            assert wait_until(lambda: client.alive() == [])     # the worker closed its sink at the end
    finally:
        sink.close()


@pytest.mark.slow
def test_a_client_rejects_a_message_that_breaks_the_schema():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    pub = plain_session(listen=endpoint)
    try:
        with Client("cam9", connect=[endpoint], multicast=False) as client:
            assert wait_until(lambda: len(list(pub.info.peers_zid())) == 1)
            time.sleep(1.0)
            pub.put("swarmpose/cam9/frame", json.dumps({"schema": "swarmpose.frame", "version": 1, "camera": "cam9"}))
            pub.put("swarmpose/cam9/frame", b"not json")
            assert wait_until(lambda: client.rejected == 2)
            assert list(client.frames(timeout=0.3)) == []
    finally:
        pub.close()


def test_malformed_endpoints_fail_at_once_with_the_value():
    with pytest.raises(PublishError, match="--connect.*foo"):
        ZenohSink("cam0", dict, connect=["foo"], multicast=False)
    taken = f"tcp/127.0.0.1:{free_port()}"
    holder = plain_session(listen=taken)
    try:
        with pytest.raises(PublishError, match="Address already in use"):
            ZenohSink("cam0", dict, listen=[taken], multicast=False)
    finally:
        holder.close()


def test_an_unreachable_router_is_reported_and_the_worker_goes_on(wave_sequence, body, tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    health = tmp_path / "status.json"
    sink = ZenohSink("cam0", dict, mode="client", connect=[endpoint], multicast=False, retry_s=0.3)
    worker = worker_on(wave_sequence, body, sink, HealthFileSink(health))
    worker.run()                                    # runs to the end without a router
    assert worker.stats.published == 6 and sink.unsent >= 6
    warning = json.loads(health.read_text())["zenoh"]["warning"]
    assert "Unable to connect" in warning and "retrying every 0.3 s" in warning and endpoint in warning


def test_a_router_that_comes_later_is_connected_by_the_retry():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    sink = ZenohSink("cam0", dict, mode="client", connect=[endpoint], multicast=False, retry_s=0.3)
    try:
        assert "Unable to connect" in sink.state()["warning"]
        router = plain_session(listen=endpoint, mode="router")
        try:
            got = []
            router.declare_subscriber("swarmpose/cam0/frame", lambda s: got.append(json.loads(s.payload.to_bytes())))
            deadline = time.monotonic() + 10
            n = 0
            while not got and time.monotonic() < deadline:
                n += 1
                sink.frame({"frame": n}, None)      # each publish attempt retries the session when due
                time.sleep(0.2)
            assert got and sink.state()["routers"] == 1 and sink.state()["warning"] == ""
        finally:
            router.close()
    finally:
        sink.close()


def test_a_restarted_router_is_reconnected_and_the_lost_connection_is_reported():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = plain_session(listen=endpoint, mode="router")
    sink = ZenohSink("cam0", dict, mode="client", connect=[endpoint], multicast=False)
    try:
        assert sink.state()["routers"] == 1 and sink.state()["warning"] == ""
        router.close()
        assert wait_until(lambda: sink.state()["routers"] == 0)
        assert sink.state()["warning"] == f"connection to {endpoint} lost; zenoh reconnects by itself"
        router = plain_session(listen=endpoint, mode="router")    # the same port again
        got = []
        router.declare_subscriber("swarmpose/cam0/frame", lambda s: got.append(json.loads(s.payload.to_bytes())))
        n = 0

        def published() -> bool:
            nonlocal n
            n += 1
            sink.frame({"frame": n}, None)
            return bool(got)

        assert wait_until(published, timeout=20.0)
        assert sink.state()["routers"] == 1 and sink.state()["warning"] == "" and sink.unsent == 0
    finally:
        sink.close()
        router.close()


def test_a_lost_connect_endpoint_is_retried_often_unless_the_zenoh_file_says():
    from swarmpose.publish.zenoh_link import zenoh_config

    retry = json.loads(zenoh_config("client", ["tcp/127.0.0.1:7447"], multicast=False).get_json("connect/retry"))
    assert retry == {"period_init_ms": 200, "period_max_ms": 1000, "period_increase_factor": 2.0}


def test_a_connect_retry_in_the_zenoh_file_wins(tmp_path):
    from swarmpose.publish.zenoh_link import zenoh_config

    path = tmp_path / "zenoh.json5"
    path.write_text("{connect: {retry: {period_init_ms: 3000, period_max_ms: 6000, period_increase_factor: 3}}}")
    retry = json.loads(zenoh_config("client", multicast=False, config_file=str(path)).get_json("connect/retry"))
    assert retry == {"period_init_ms": 3000, "period_max_ms": 6000, "period_increase_factor": 3.0}


def test_peer_mode_with_an_unreachable_connect_endpoint_warns():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    sink = ZenohSink("cam0", dict, connect=[endpoint], multicast=False)
    try:
        assert "no --connect endpoint reachable yet" in sink.state()["warning"]
    finally:
        sink.close()


@pytest.mark.slow
def test_serve_configured_by_environment_publishes_and_stops_on_sigterm(wave_sequence, tmp_path):
    """The docker entry point (`swarmpose serve`, settings from SWARMPOSE_*), run outside docker."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    health = tmp_path / "status.json"
    env = {"PATH": str(Path(sys.executable).parent), "HOME": str(tmp_path), "SWARMPOSE_SOURCE": str(wave_sequence),
           "SWARMPOSE_CAMERA_ID": "envcam", "SWARMPOSE_LISTEN": endpoint, "SWARMPOSE_MULTICAST": "false",
           "SWARMPOSE_MODE": "lift", "SWARMPOSE_RATE": "5", "SWARMPOSE_LOOP": "true",
           "SWARMPOSE_HEALTH_FILE": str(health), "SWARMPOSE_STATUS_PERIOD_S": "0.5"}
    proc = subprocess.Popen([str(Path(sys.executable).parent / "swarmpose"), "serve"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sub = plain_session(connect=endpoint)
    frames, alive = [], []
    sub.declare_subscriber("swarmpose/envcam/frame", lambda s: frames.append(json.loads(s.payload.to_bytes())))
    sub.liveliness().declare_subscriber("swarmpose/envcam/alive", lambda s: alive.append(str(s.kind)), history=True)
    try:
        assert wait_until(lambda: len(frames) >= 8, timeout=60), proc.stderr.read() if proc.poll() else "no frames"
        for message in frames:
            jsonschema.validate(message, SCHEMAS["frame"])
        assert {m["camera"] for m in frames} == {"envcam"}
        numbers = [m["frame"] for m in frames]
        assert any(b < a for a, b in zip(numbers, numbers[1:])), numbers     # --loop started the recording over
        healthy = subprocess.run([str(Path(sys.executable).parent / "swarmpose"), "health"], env=env,
                                 capture_output=True, text=True, timeout=60)
        assert healthy.returncode == 0 and healthy.stdout.startswith("healthy: running")
        proc.terminate()
        assert proc.wait(timeout=30) == 0
        assert wait_until(lambda: "SampleKind.DELETE" in alive)
        assert json.loads(health.read_text())["state"] == "stopping"
    finally:
        if proc.poll() is None:
            proc.kill()
        sub.close()


def test_frames_that_arrive_after_the_workers_end_are_still_delivered():
    """zenoh does not order a liveliness token's end after the frames published before it (the demo's
    subscriber once got 2 of 3 frames): a frame that comes within END_GRACE_S of the end is delivered,
    and the iterator then stops without waiting for its timeout."""
    from swarmpose.publish.client import _WORKERS_ENDED

    with Client("cam7", listen=[f"tcp/127.0.0.1:{free_port()}"], multicast=False) as client:
        client.ended, client.live = {"cam7"}, set()  # the worker's token went away ...
        client._enqueue(_WORKERS_ENDED)
        late = {"schema": "swarmpose.frame", "frame": 41}
        timer = threading.Timer(0.3, client._enqueue, [late])  # ... before its last frame arrived
        timer.start()
        assert list(client.frames(timeout=600, until_workers_end=True)) == [late]
        timer.join()
