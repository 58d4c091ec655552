"""zenoh sessions: configuration shared by the worker and the client, and the worker's publisher.

:func:`zenoh_config` builds a ``zenoh.Config`` from the options every zenoh program shares
(``--mode``, ``--connect``, ``--listen``, multicast scouting, a JSON5 file). :class:`ZenohSink`
publishes a worker's messages (see ``protocol/README.md``):

* ``swarmpose/<camera>/frame`` — every frame message, ``application/json``;
* ``swarmpose/<camera>/status`` — every status message;
* ``swarmpose/<camera>/alive`` — a liveliness token while the sink is open;
* ``swarmpose/<camera>/info`` — a queryable answering with the current info message.

A router that cannot be reached is not fatal: in client mode zenoh refuses to open, so the
sink retries every ``retry_s`` seconds (frames meanwhile are counted as ``unsent``) and says
so in :meth:`ZenohSink.state`; in peer mode the session opens and zenoh keeps trying the
``connect`` endpoints itself. A router lost once the session is open (killed, restarted) is
reconnected by zenoh, every 0.2 s backing off to 1 s (``RECONNECT``); meanwhile the state says
the connection is lost and frames are not delivered. Malformed endpoints, a zenoh file that does
not parse and a listen address that cannot be bound raise
:class:`~swarmpose.core.errors.PublishError` at once.

Every info query that reaches the queryable is finalised when its callback returns (the querier
learns at once that no more replies come), answered with an error reply when the info message
cannot be made, and :meth:`ZenohSink.close` lets the answers in progress go out (up to
``ANSWER_GRACE_S``) before the session closes.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable, Sequence

from swarmpose.core.errors import PublishError
from swarmpose.messages import encode, keys
from swarmpose.sources.base import Frame, exc_message

UNREACHABLE = "Unable to connect"
RECONNECT = {"period_init_ms": 200, "period_max_ms": 1000, "period_increase_factor": 2}
"""How often zenoh tries a lost ``--connect`` endpoint again (a restarted router), unless the
zenoh file says: zenoh's own default backs off to 4 s between tries, which delays frames
by seconds after a router restart (``scripts/router_restart.py`` measures it)."""
ANSWER_GRACE_S = 2.0
"""Seconds :meth:`ZenohSink.close` waits for info queries being answered."""


def zenoh_config(mode: str = "peer", connect: Sequence[str] = (), listen: Sequence[str] = (),
                 multicast: bool = True, config_file: str = ""):
    """A ``zenoh.Config``: ``config_file`` (JSON5) first, then mode, endpoints and scouting.

    mode: peer or client; connect / listen: endpoints such as ``tcp/127.0.0.1:7447``;
    multicast: multicast scouting (automatic discovery of peers and routers on the LAN); a lost
    ``connect`` endpoint is tried again every 0.2 s, backing off to 1 s (``RECONNECT``; a
    ``connect/retry`` in the file wins).
    Raises PublishError naming the bad value.
    """
    import zenoh

    if mode not in ("peer", "client"):
        raise PublishError(f"zenoh mode must be peer or client, got {mode!r}")
    try:
        config = zenoh.Config.from_file(config_file) if config_file else zenoh.Config()
    except zenoh.ZError as exc:
        raise PublishError(f"zenoh config file {config_file}: {_short(exc)}; pass a valid JSON5 zenoh "
                           "configuration") from None
    if config.get_json("connect/retry") in (None, "null"):
        config.insert_json5("connect/retry", json.dumps(RECONNECT))
    for key, value, what in (("mode", mode, "--mode"), ("connect/endpoints", list(connect), "--connect"),
                             ("listen/endpoints", list(listen), "--listen"),
                             ("scouting/multicast/enabled", bool(multicast), "multicast")):
        if key.endswith("endpoints") and not value:
            continue
        try:
            config.insert_json5(key, json.dumps(value))
        except zenoh.ZError as exc:
            raise PublishError(f"zenoh {what} {value!r}: {_short(exc)} (endpoints look like tcp/HOST:PORT)") from None
    return config


def _short(exc: BaseException) -> str:
    """zenoh's message without its Rust source locations."""
    text = exc_message(exc).replace("Json5Err(Message { msg: ", "")
    return text.split(" at /")[0].strip().strip('"')


def open_session(config, what: str = "zenoh"):
    """``zenoh.open(config)``; PublishError with zenoh's reason (and whether it is worth a retry)."""
    import zenoh

    try:
        return zenoh.open(config)
    except zenoh.ZError as exc:
        reason = _short(exc)
        hint = ("start the zenoh router or fix --connect" if UNREACHABLE in reason
                else "check --listen/--connect (is the port taken?)")
        raise PublishError(f"{what}: cannot open a zenoh session: {reason}; {hint}") from None


class ZenohSink:
    """Publishes a worker's messages on zenoh for camera ``camera``.

    info: a callable returning the current info message (called for every query).
    """

    def __init__(self, camera: str, info: Callable[[], dict], *, mode: str = "peer", connect: Sequence[str] = (),
                 listen: Sequence[str] = (), multicast: bool = True, config_file: str = "", retry_s: float = 5.0):
        self.camera, self.info, self.retry_s = camera, info, retry_s
        self.mode, self.connect, self.listen = mode, tuple(connect), tuple(listen)
        self.keys = keys(camera)
        self._config_args = (mode, self.connect, self.listen, multicast, config_file)
        zenoh_config(*self._config_args)  # a malformed endpoint or file fails here, before any frame
        self._lock = threading.Lock()
        self._session = None
        self._publishers: dict = {}
        self._handles: list = []
        self.error = ""
        self.unsent = 0
        self._next_try = 0.0
        self._closed = False
        self._answers = threading.Condition()  # guards _answering and the _closed seen by _answer
        self._answering = 0
        self._was_connected = False  # a router or peer was seen: its absence now is a lost connection
        self._try_open(first=True)

    # ------------------------------------------------------------------ session
    def _try_open(self, first: bool = False) -> None:
        import zenoh

        if self._session is not None or self._closed or time.monotonic() < self._next_try:
            return
        try:
            session = open_session(zenoh_config(*self._config_args), f"camera {self.camera}")
        except PublishError as exc:
            if first and UNREACHABLE not in str(exc):
                raise
            self.error = f"{exc} (retrying every {self.retry_s:g} s)"
            self._next_try = time.monotonic() + self.retry_s
            return
        json_enc = zenoh.Encoding.APPLICATION_JSON
        self._publishers = {kind: session.declare_publisher(self.keys[kind], encoding=json_enc)
                            for kind in ("frame", "status")}
        self._handles = [session.liveliness().declare_token(self.keys["alive"]),
                         session.declare_queryable(self.keys["info"], self._answer)]
        self._session, self.error = session, ""

    def _answer(self, query) -> None:
        """zenoh's callback thread: reply with the info message (an error reply when it cannot be made)."""
        import zenoh

        with query:  # finalised on exit, not whenever Python frees it: the querier stops waiting at once
            with self._answers:
                if self._closed:  # closing: no reply, the query is finalised
                    return
                self._answering += 1
            try:
                query.reply(self.keys["info"], encode(self.info()), encoding=zenoh.Encoding.APPLICATION_JSON)
            except Exception as exc:  # a failing reply must not take the zenoh callback thread down
                self.error = f"info query failed: {exc_message(exc)}"
                try:
                    query.reply_err(f"camera {self.camera}: {self.error}")
                except Exception:  # the session is gone
                    pass
            finally:
                with self._answers:
                    self._answering -= 1
                    self._answers.notify_all()

    def _put(self, kind: str, message: dict) -> None:
        with self._lock:
            self._try_open()
            if self._session is None:
                self.unsent += 1
                return
            self._publishers[kind].put(encode(message))

    # ------------------------------------------------------------------ Sink
    def frame(self, message: dict, frame: Frame | None) -> None:
        """Publish a frame message on ``swarmpose/<camera>/frame``."""
        self._put("frame", message)

    def status(self, message: dict) -> None:
        """Publish a status message on ``swarmpose/<camera>/status``."""
        self._put("status", message)

    def state(self) -> dict:
        """The ``zenoh`` part of a status message: mode, endpoints, connected peers/routers, warning."""
        peers = routers = 0
        session = self._session
        if session is not None:
            try:
                peers, routers = len(list(session.info.peers_zid())), len(list(session.info.routers_zid()))
            except Exception:  # the session may be closing
                pass
        warning = self.error
        if not warning and self.connect and peers + routers == 0:
            where = ", ".join(self.connect)
            warning = (f"connection to {where} lost; zenoh reconnects by itself" if self._was_connected
                       else f"no --connect endpoint reachable yet ({where}); zenoh keeps trying")
        self._was_connected |= peers + routers > 0
        return {"mode": self.mode, "connect": list(self.connect), "listen": list(self.listen), "peers": peers,
                "routers": routers, "warning": warning}

    def frames_subscribed(self) -> bool:
        """True while some subscriber matches this camera's frame key (zenoh's matching status)."""
        publisher = self._publishers.get("frame")
        if publisher is None:
            return False
        try:
            return bool(publisher.matching_status.matching)
        except Exception:  # the session may be closing
            return False

    def close(self) -> None:
        """Withdraw the liveliness token and close the session (idempotent). Info queries being
        answered get their reply first (waits up to ``ANSWER_GRACE_S``); later ones get none."""
        with self._lock:
            with self._answers:
                self._closed = True
                self._answers.wait_for(lambda: self._answering == 0, ANSWER_GRACE_S)
            session, self._session = self._session, None
            for handle in self._handles + list(self._publishers.values()):
                try:
                    handle.undeclare()
                except Exception:  # already gone with the session
                    pass
            self._handles, self._publishers = [], {}
            if session is not None:
                session.close()
