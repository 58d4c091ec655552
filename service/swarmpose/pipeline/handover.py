"""One-item queues between the worker's threads."""

from __future__ import annotations

import threading
import time

END = object()
"""What :meth:`Handover.get` returns after the last item (or after an abort)."""


class Handover:
    """A one-item queue between two threads.

    drop_stale: ``put`` replaces a waiting item (returns False: one was dropped) instead of
    waiting for the consumer. ``finish()`` lets ``get`` return :data:`END` once the last item
    is taken; ``abort()`` makes every waiting call return at once (``get`` gives END).
    """

    def __init__(self, drop_stale: bool):
        self.drop_stale = drop_stale
        self._cond = threading.Condition()
        self._item: object | None = None
        self._full = False
        self._finished = False
        self._aborted = False

    def put(self, item: object) -> bool:
        """Hand ``item`` over; False when a waiting older item was dropped for it."""
        with self._cond:
            dropped = False
            if self._full and self.drop_stale:
                dropped = True
            else:
                while self._full and not self._aborted:
                    self._cond.wait()
            if self._aborted:
                return True
            self._item, self._full = item, True
            self._cond.notify_all()
            return not dropped

    def get(self, timeout: float | None = None) -> object:
        """The next item, waiting for it; END after ``finish()`` or ``abort()``; with ``timeout`` (s),
        None when nothing came within it."""
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._cond:
            while not self._full and not self._finished and not self._aborted:
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    return None
                self._cond.wait(left)
            if self._aborted or not self._full:
                return END
            item, self._item, self._full = self._item, None, False
            self._cond.notify_all()
            return item

    def finish(self) -> None:
        """No more items will come: ``get`` returns END once the waiting one is taken."""
        with self._cond:
            self._finished = True
            self._cond.notify_all()

    def abort(self) -> None:
        """Wake every waiting call; nothing more is handed over."""
        with self._cond:
            self._aborted = True
            self._cond.notify_all()
