"""Which driver runs which feature: the one table every refusal and every command's flags come from.

Drivers:

- ``offline``: every frame in order, one thread, the whole recording at hand (``track``, ``eval``,
  ``personalize``, :func:`swarmpose.track`);
- ``threaded``: detection and tracking in two threads, nothing waits for later frames (``serve``,
  ``replay``);
- ``frame_by_frame``: the caller hands in one frame at a time (:meth:`swarmpose.Tracker.track_frame`).

A feature that needs the frames after the current one (the backward pass, centred smoothing) runs
only offline; the ensemble runs its tracks in one thread, so not in the threaded worker. A command
whose driver cannot run a feature does not offer its flag (:func:`unavailable_settings`); a
configuration that asks for it anyway (a config file, the environment, the API) gets a
:class:`~swarmpose.core.errors.ConfigError` from :func:`refuse` that says where it runs.
"""

from __future__ import annotations

from dataclasses import dataclass

from swarmpose.core.errors import ConfigError
from swarmpose.tracking.config import TrackerConfig, tracker_default

WHERE = {"offline": "offline runs", "threaded": "serve and replay", "frame_by_frame": "Tracker.track_frame"}
"""Each driver and what it is called in a refusal."""
DRIVERS = tuple(WHERE)


@dataclass(frozen=True)
class Feature:
    """A feature some drivers cannot run.

    setting: the tracker setting that asks for it; value: the value that does (None: any but the
    default); drivers: those that run it; why: what the others lack; instead: where to run it."""

    setting: str
    drivers: tuple[str, ...]
    why: str
    instead: str
    value: str | None = None

    def asked(self, config: TrackerConfig) -> bool:
        """Whether ``config`` asks for this feature."""
        value = getattr(config, self.setting)
        if self.value is not None:
            return value == self.value
        return value != tracker_default(self.setting)

    def describe(self, config: TrackerConfig) -> str:
        """``setting = value`` as ``config`` has it."""
        return f"{self.setting} = {getattr(config, self.setting)}"


FEATURES = (
    Feature("backward", ("offline",), "the backward pass publishes frames late and needs the frames after each one",
            "`swarmpose track SOURCE --out DIR --backward N` (the files of replay) or swarmpose.track(source, "
            "backward=N); or set backward 0"),
    Feature("ensemble", ("offline", "frame_by_frame"), "the ensemble runs its tracks in one thread, and serve and "
            "replay detect and track in two", "`swarmpose track SOURCE --out DIR --ensemble N` (the files of "
            "replay) or the Python API's Tracker; or set ensemble 1"),
    Feature("smoothing", ("offline",), "centred smoothing averages each pose with the frames after it",
            "`swarmpose track SOURCE --out DIR --smoothing centred` (the files of replay) or swarmpose.track(source, "
            "smoothing='centred'); or smoothing one-euro live", value="centred"),
)
"""Every feature that some driver cannot run."""

def refuse(driver: str, config: TrackerConfig) -> None:
    """ConfigError naming the first feature ``config`` asks for that ``driver`` cannot run."""
    if driver not in DRIVERS:
        raise ValueError(f"unknown driver {driver!r}; drivers are {', '.join(DRIVERS)}")
    for feature in FEATURES:
        if driver not in feature.drivers and feature.asked(config):
            raise ConfigError(f"{feature.describe(config)}: not in {WHERE[driver]}: {feature.why}; run "
                              f"{feature.instead}")


def unavailable_settings(driver: str) -> tuple[str, ...]:
    """The tracker settings whose every non-default value ``driver`` refuses: the flags its commands
    do not offer (a feature of one value, such as centred smoothing, keeps its setting's flag)."""
    return tuple(f.setting for f in FEATURES if driver not in f.drivers and f.value is None)
