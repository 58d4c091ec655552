"""A body fitted to the person while they are tracked: what a :class:`~swarmpose.tracking.body_tracker.BodyTracker`
asks of its ``fitting`` (the automatic height, online personalisation: :mod:`swarmpose.personalise`).

The tracker calls :meth:`BodyFitting.attach` once, :meth:`~BodyFitting.after_frame` as the last step
of every frame, :meth:`~BodyFitting.new_person` when it is reused for another person, and
:meth:`~BodyFitting.personalisation` for the status and info messages. A fitting changes the
tracker's body only through :meth:`BodyTracker.set_body`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from swarmpose.detect.joints import Joints2D
    from swarmpose.sources.base import Frame
    from swarmpose.tracking.body_tracker import BodyTracker
    from swarmpose.tracking.result import BodyResult


class BodyFitting(Protocol):
    """Fits a tracker's body to its person (see the module docstring)."""

    def attach(self, tracker: BodyTracker) -> None:
        """Called once, when ``tracker`` is made with this fitting (its body is the tracking one)."""

    def after_frame(self, tracker: BodyTracker, frame: Frame, joints: Joints2D | None, others_removed: bool,
                    result: BodyResult) -> None:
        """Called with each frame's result (others_removed: other people's pixels left the depth)."""

    def new_person(self, tracker: BodyTracker) -> None:
        """``tracker`` follows another person from now on: start the fit afresh."""

    def personalisation(self, tracker: BodyTracker) -> dict:
        """The fit's state as the status and info messages' ``personalisation`` reports it."""
