"""What the worker hands its results to: a :class:`Sink` (zenoh, files, video, progress)."""

from __future__ import annotations

from typing import Protocol

from swarmpose.sources.base import Frame


class Sink(Protocol):
    """Receives every frame message (in frame order) and every status message.

    ``frame(message, frame)``: a ``swarmpose.frame`` message (protocol/frame.schema.json)
    and the :class:`~swarmpose.sources.base.Frame` it was made from (None for a frame the
    source could not deliver). ``status(message)``: a ``swarmpose.status`` message.
    ``close()``: flush and release; called once, also after errors. A sink raises
    :class:`~swarmpose.core.errors.OutputError` when it cannot write; the worker reports that
    once (on the status and the log), hands that sink nothing more (it is still closed) and
    goes on with its other sinks.
    """

    def frame(self, message: dict, frame: Frame | None) -> None: ...

    def status(self, message: dict) -> None: ...

    def close(self) -> None: ...
