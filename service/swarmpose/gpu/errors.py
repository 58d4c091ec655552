"""Errors of the OpenCL layer, part of the :mod:`swarmpose.core.errors` hierarchy."""

from __future__ import annotations

from swarmpose.core.errors import SwarmposeError


class DeviceError(SwarmposeError):
    """No OpenCL platform, or no device matching the requested ``--device`` spec."""


class KernelBuildError(SwarmposeError):
    """An OpenCL program failed to build; carries the file, options, device and build log."""

    def __init__(self, filename: str, options: tuple[str, ...], device: str, log: str):
        self.filename = filename
        self.options = tuple(options)
        self.device = device
        self.log = log
        super().__init__(f"building {filename} for {device} with options {' '.join(options) or '(none)'} "
                         f"failed:\n{log.strip()}")
