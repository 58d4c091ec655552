"""Choosing an OpenCL device and making its context and queue.

A device *spec* is the ``device`` setting (``--device``, ``SWARMPOSE_DEVICE`` or its older
name ``SWARMPOSE_CL_DEVICE``; the environment is read where settings are loaded, never here):

* ``None`` / empty: the first GPU if any, else a CPU device (PoCL preferred), else anything;
* ``cpu`` or ``gpu``: the first device of that type (PoCL first among CPUs);
* ``P:D``: device ``D`` of platform ``P`` (indices as :func:`list_devices` prints them);
* anything else: the first device whose device or platform name, vendor or version contains
  the text (case-insensitive), e.g. ``pocl``, ``nvidia``, ``rtx``.

Nothing matching, or no OpenCL platform at all, raises :class:`DeviceError` listing what is
available and how to get a CPU device (``pip install pocl-binary-distribution``).

:class:`ClContext` is the explicit handle the scorer works with: one device, its context,
its profiling queue and the programs built for it (memoised per context, at most
:data:`MAX_PROGRAMS`). :meth:`ClContext.for_spec` shares one context per device among
the trackers of a process (at most :data:`MAX_CONTEXTS` devices are kept).
"""

from __future__ import annotations

import functools
import os
from collections import OrderedDict
from dataclasses import dataclass

from swarmpose.gpu.errors import DeviceError
from swarmpose.gpu.program import compile_program, define_options

MAX_PROGRAMS = 16
"""Built programs kept per context (least recently used dropped first)."""
MAX_CONTEXTS = 4
"""Devices whose shared context :meth:`ClContext.for_spec` keeps."""
POCL_HINT = ("install a CPU OpenCL driver with 'pip install pocl-binary-distribution' (Linux) "
             "or a GPU vendor's OpenCL ICD")


@dataclass(frozen=True)
class DeviceInfo:
    """One OpenCL device: platform/device indices, names and type ('gpu', 'cpu', 'other')."""

    platform_index: int
    device_index: int
    platform: str
    name: str
    kind: str
    search_text: str = ""

    def __str__(self) -> str:
        return f"{self.platform_index}:{self.device_index} {self.kind} '{self.name}' on '{self.platform}'"


def _kind(device) -> str:
    import pyopencl as cl

    if device.type & cl.device_type.GPU:
        return "gpu"
    if device.type & cl.device_type.CPU:
        return "cpu"
    return "other"


def pin_pocl_threads() -> bool:
    """Ask PoCL's CPU driver to pin its worker threads (``POCL_AFFINITY=1``: thread i on CPU i)
    unless the environment already says; only where this process may run on every CPU
    0..N-1, as PoCL aborts when a pinning is refused (a container limited to other CPUs).
    Unpinned, the kernel can run at half speed for a while after a process starts
    (``scripts/pocl_pinning.py`` measures it). PoCL reads it when it starts, at the first
    platform query.
    Returns whether it is set to pin."""
    if "POCL_AFFINITY" not in os.environ:
        try:
            allowed = os.sched_getaffinity(0)
        except (AttributeError, OSError):  # not Linux
            return False
        if allowed == set(range(os.cpu_count() or 0)):
            os.environ["POCL_AFFINITY"] = "1"
    return os.environ.get("POCL_AFFINITY") == "1"


def _platforms() -> list:
    import pyopencl as cl

    pin_pocl_threads()
    try:
        return list(cl.get_platforms())
    except cl.Error as exc:  # no ICD loader entries: PLATFORM_NOT_FOUND_KHR
        raise DeviceError(f"no OpenCL platform found ({exc}); {POCL_HINT}") from exc


def _all_devices() -> list[tuple[DeviceInfo, object]]:
    import pyopencl as cl

    out = []
    for pi, plat in enumerate(_platforms()):
        try:
            devices = plat.get_devices()
        except cl.Error:  # a platform without devices
            continue
        for di, dev in enumerate(devices):
            text = " ".join([plat.name, plat.vendor, plat.version, dev.name, dev.vendor]).lower()
            out.append((DeviceInfo(pi, di, plat.name.strip(), dev.name.strip(), _kind(dev), text), dev))
    return out


def list_devices() -> list[DeviceInfo]:
    """Every OpenCL device of every platform, in platform/device order."""
    return [info for info, _ in _all_devices()]


def _available(devices) -> str:
    return "; ".join(str(info) for info, _ in devices) or "none"


def choose_device(spec: str | None = None):
    """The ``pyopencl.Device`` named by ``spec`` (see the module docstring; None or "": the default)."""
    devices = _all_devices()
    if not devices:
        raise DeviceError(f"OpenCL platforms exist but offer no device; {POCL_HINT}")
    text = (spec or "").strip().lower()
    pocl_first = sorted(devices, key=lambda d: "portable computing" not in d[0].platform.lower())
    if not text:
        for want in ("gpu", "cpu"):
            found = [d for info, d in pocl_first if info.kind == want]
            if found:
                return found[0]
        return devices[0][1]
    if text in ("gpu", "cpu"):
        found = [d for info, d in pocl_first if info.kind == text]
        if found:
            return found[0]
        raise DeviceError(f"no OpenCL {text.upper()} device (device spec {spec!r}); available: "
                          f"{_available(devices)}" + ("; " + POCL_HINT if text == "cpu" else ""))
    if ":" in text:
        try:
            pi, di = (int(x) for x in text.split(":", 1))
        except ValueError:
            pi = di = None
        if pi is not None:
            for info, dev in devices:
                if (info.platform_index, info.device_index) == (pi, di):
                    return dev
            raise DeviceError(f"no OpenCL device {spec!r} (PLATFORM:DEVICE); available: {_available(devices)}")
    for info, dev in devices:
        if text in info.search_text:
            return dev
    raise DeviceError(f"no OpenCL device matches {spec!r} (use cpu, gpu, PLATFORM:DEVICE or part of a name); "
                      f"available: {_available(devices)}")


class ClContext:
    """One OpenCL device with its context, profiling queue and built programs.

    device: a ``pyopencl.Device``. Use :meth:`for_spec` to share one per device.
    """

    def __init__(self, device):
        import pyopencl as cl

        self.device = device
        self.context = cl.Context([device])
        self.queue = cl.CommandQueue(self.context, device, properties=cl.command_queue_properties.PROFILING_ENABLE)
        self._programs: OrderedDict[tuple, object] = OrderedDict()

    @staticmethod
    def for_spec(spec: str | None = None) -> ClContext:
        """The shared context of the device ``spec`` names (see the module docstring)."""
        return _shared_context(choose_device(spec))

    @property
    def name(self) -> str:
        """``platform: device``, as the status and info messages report it."""
        return f"{self.device.platform.name.strip()}: {self.device.name.strip()}"

    @property
    def is_cpu(self) -> bool:
        import pyopencl as cl

        return bool(self.device.type & cl.device_type.CPU)

    def program(self, filename: str, defines: dict[str, object] | None = None, extra_options: tuple[str, ...] = ()):
        """The built ``pyopencl.Program`` of ``cl/<filename>`` with ``-D`` ``defines`` and other
        build flags, memoised in this context; a failed build raises KernelBuildError."""
        options = define_options(defines or {}) + tuple(extra_options)
        key = (filename, options)
        if key in self._programs:
            self._programs.move_to_end(key)
            return self._programs[key]
        program = compile_program(self.context, filename, options)
        self._programs[key] = program
        while len(self._programs) > MAX_PROGRAMS:
            self._programs.popitem(last=False)
        return program


@functools.lru_cache(maxsize=MAX_CONTEXTS)
def _shared_context(device) -> ClContext:
    return ClContext(device)


def describe(device) -> str:
    """``'device name (platform name)'`` for reports."""
    return f"{device.name.strip()} ({device.platform.name.strip()})"
