"""Subscribe to swarmpose workers over zenoh: frames, status, info, liveliness.

    from swarmpose.publish.client import Client

    with Client(camera="*", connect=["tcp/192.168.1.10:7447"]) as client:
        print(client.info())                      # one info message per live worker
        for frame in client.frames(timeout=10):   # decoded swarmpose.frame messages (dicts)
            for body in frame["bodies"]:
                print(frame["camera"], frame["frame"], body["state"], body["joints"]["head"]["position_m"])

or with callbacks: ``client.on_frame(fn)`` / ``client.on_status(fn)``. Messages are
validated against protocol/*.schema.json unless ``validate=False``; a message that fails
is counted in ``client.rejected`` with its error in ``client.last_error`` and not delivered.

``python -m swarmpose.publish.client`` (or ``swarmpose subscribe``) prints poses as they arrive.
"""

from __future__ import annotations

import queue
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence

from swarmpose.core.errors import ProtocolError
from swarmpose.messages import check_camera_id, decode, keys, validate
from swarmpose.publish.zenoh_link import open_session, zenoh_config
from swarmpose.publish.zenoh_options import add_zenoh_options  # noqa: F401 (the client's tools take them from here)

QUEUE_SIZE = 256
END_GRACE_S = 1.0
"""After every worker has ended, frames are still taken until none has come for this long: zenoh
does not order a liveliness token's end after the data its worker published before it."""
_WORKERS_ENDED: dict = {"schema": "swarmpose.client.workers-ended"}
"""Queued after the last live worker's liveliness token went away (ends ``frames(until_workers_end=True)``)."""


class Client:
    """A zenoh session subscribed to camera ``camera`` (``*`` = every camera).

    mode: peer (default) or client (through a router); connect / listen: zenoh endpoints;
    multicast: multicast scouting; config_file: a zenoh JSON5 file; validate: check every
    message against its schema. The iterator keeps at most 256 frames; older ones are
    dropped when the consumer falls behind (counted in ``dropped``). The client follows the
    workers' liveliness tokens: ``live`` holds the cameras whose worker runs, ``ended`` those
    whose worker has stopped (or vanished) since the client saw it.
    """

    def __init__(self, camera: str = "*", *, mode: str = "peer", connect: Sequence[str] = (),
                 listen: Sequence[str] = (), multicast: bool = True, config_file: str = "", validate: bool = True):
        if camera != "*":
            check_camera_id(camera)
        self.camera, self.validate = camera, validate
        self.keys = keys(camera)
        self.rejected, self.dropped, self.last_error = 0, 0, ""
        self._frames: queue.Queue[dict] = queue.Queue(QUEUE_SIZE)
        self._callbacks: dict[str, list[Callable[[dict], None]]] = {"frame": [], "status": []}
        self._lock = threading.Lock()
        self.session = open_session(zenoh_config(mode, connect, listen, multicast, config_file), "client")
        self.live: set[str] = set()
        self.ended: set[str] = set()
        self._subscribers = [self.session.declare_subscriber(self.keys["frame"], self._on("frame")),
                             self.session.declare_subscriber(self.keys["status"], self._on("status")),
                             self.session.liveliness().declare_subscriber(self.keys["alive"], self._on_alive,
                                                                          history=True)]

    # ------------------------------------------------------------------ receiving
    def _on(self, kind: str) -> Callable:
        def handler(sample) -> None:
            try:
                message = decode(sample.payload.to_bytes())
                if self.validate:
                    validate(message)
                elif message.get("schema") != f"swarmpose.{kind}":
                    raise ProtocolError(f"expected a swarmpose.{kind} message, got {message.get('schema')!r}")
            except ProtocolError as exc:
                with self._lock:
                    self.rejected += 1
                    self.last_error = f"{sample.key_expr}: {exc}"
                return
            if kind == "frame":
                self._enqueue(message)
            for callback in list(self._callbacks[kind]):
                try:
                    callback(message)
                except Exception as exc:  # a user callback must not kill zenoh's thread
                    self.last_error = f"{kind} callback raised {type(exc).__name__}: {exc}"
        return handler

    def _on_alive(self, sample) -> None:
        """A worker's liveliness token appeared (PUT) or went away (DELETE: it stopped or vanished)."""
        import zenoh  # here, as in zenoh_link: `swarmpose` commands that never subscribe do not load zenoh

        camera = str(sample.key_expr).split("/")[1]
        with self._lock:
            if sample.kind == zenoh.SampleKind.DELETE:
                if camera in self.live:
                    self.live.discard(camera)
                    self.ended.add(camera)
                    if not self.live:
                        self._enqueue(_WORKERS_ENDED)
            else:
                self.live.add(camera)
                self.ended.discard(camera)

    @property
    def workers_ended(self) -> bool:
        """Every worker the client saw has ended (and one was seen)."""
        return bool(self.ended) and not self.live

    def _enqueue(self, message: dict) -> None:
        while True:
            try:
                self._frames.put_nowait(message)
                return
            except queue.Full:
                try:
                    self._frames.get_nowait()
                    self.dropped += 1
                except queue.Empty:
                    pass

    def on_frame(self, callback: Callable[[dict], None]) -> None:
        """Call ``callback(frame_message)`` for every frame (on zenoh's thread: keep it short)."""
        self._callbacks["frame"].append(callback)

    def on_status(self, callback: Callable[[dict], None]) -> None:
        """Call ``callback(status_message)`` for every status message."""
        self._callbacks["status"].append(callback)

    def frames(self, timeout: float | None = None, count: int | None = None,
               until_workers_end: bool = False) -> Iterator[dict]:
        """Frame messages as they arrive; stops after ``count`` frames, when none came for
        ``timeout`` seconds (None: wait forever), or, with ``until_workers_end``, once every
        worker the client had seen has ended and no frame has come for :data:`END_GRACE_S` (the
        frames they sent before their end, which may arrive after it, are delivered first)."""
        got, ended = 0, False
        while count is None or got < count:
            try:
                message = self._frames.get(timeout=END_GRACE_S if ended else timeout)
            except queue.Empty:
                if ended and not self.workers_ended:  # a worker came back meanwhile: wait as asked
                    ended = False
                    continue
                return
            if message is _WORKERS_ENDED:
                ended = until_workers_end and self.workers_ended
                continue
            got += 1
            yield message

    # ------------------------------------------------------------------ asking
    def info(self, timeout: float = 3.0) -> list[dict]:
        """The info messages of the workers that answer; asks again (for up to ``timeout`` seconds)
        while none has, since a session just opened may not have learnt of the workers yet."""
        deadline = time.monotonic() + timeout
        replies: list[dict] = []
        answered = False
        while not answered:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                break
            started = time.monotonic()
            for reply in self.session.get(self.keys["info"], timeout=remaining):
                if reply.ok is None:
                    continue
                answered = True
                try:
                    message = decode(reply.ok.payload.to_bytes())
                    replies.append(validate(message) if self.validate else message)
                except ProtocolError as exc:
                    self.rejected += 1
                    self.last_error = str(exc)
            if not answered:
                time.sleep(max(0.0, 0.2 - (time.monotonic() - started)))
        return replies

    def alive(self, timeout: float = 2.0) -> list[str]:
        """Cameras whose worker holds its liveliness token now."""
        cameras = []
        for reply in self.session.liveliness().get(self.keys["alive"], timeout=timeout):
            if reply.ok is not None:
                cameras.append(str(reply.ok.key_expr).split("/")[1])
        return sorted(cameras)

    def close(self) -> None:
        """Undeclare the subscriptions and close the session (idempotent)."""
        for sub in self._subscribers:
            try:
                sub.undeclare()
            except Exception:  # already closed
                pass
        self._subscribers = []
        self.session.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def format_frame(message: dict, joints: Sequence[str] = ("head", "left_wrist", "right_wrist")) -> str:
    """One line per frame: camera, frame, latency, and per body its state and a few joints (m)."""
    parts = [f"{message['camera']} frame {message['frame']:>5} latency {message['latency_ms']:6.1f} ms"]
    if not message["bodies"]:
        parts.append(f"no body ({message['reason'] or 'none tracked'})")
    for body in message["bodies"]:
        where = []
        for name in joints:
            p = body["joints"].get(name, {}).get("position_m")
            where.append(f"{name} " + ("   --" if p is None else "({:+.2f} {:+.2f} {:+.2f})".format(*p)))
        parts.append(f"body {body['id']} {body['state']:<8} " + "  ".join(where))
    return "  ".join(parts)


def say(line: str) -> None:
    """Print one whole line at once (zenoh's callback thread prints too)."""
    sys.stdout.write(line + "\n")
    sys.stdout.flush()
