"""Device choice and kernel building (swarmpose.gpu.context / program) on PoCL's CPU device."""

from __future__ import annotations

import os

import pyopencl as cl
import pytest

from swarmpose.core.errors import SwarmposeError
from swarmpose.gpu import context
from swarmpose.gpu.context import MAX_PROGRAMS, ClContext, choose_device, list_devices
from swarmpose.gpu.errors import DeviceError, KernelBuildError
from swarmpose.gpu.program import define_options, read_source


def test_device_specs(monkeypatch):
    monkeypatch.setenv("SWARMPOSE_CL_DEVICE", "no-such-device")  # the environment is read by settings only
    devices = list_devices()
    assert devices, "PoCL should provide a CPU device"
    cpu = choose_device("cpu")
    assert cpu.type & cl.device_type.CPU
    first = devices[0]
    assert choose_device(f"{first.platform_index}:{first.device_index}").int_ptr == \
        cl.get_platforms()[first.platform_index].get_devices()[first.device_index].int_ptr
    assert choose_device("pocl").int_ptr == cpu.int_ptr  # matches the platform's version string
    assert choose_device(first.name[:6].upper()).name.strip() == first.name
    default = choose_device(None)
    gpus = [d for d in devices if d.kind == "gpu"]
    assert bool(default.type & cl.device_type.GPU) == bool(gpus)
    assert choose_device("").int_ptr == default.int_ptr


def test_unknown_devices_list_what_exists():
    for spec in ("no-such-device", "9:9"):
        with pytest.raises(DeviceError, match="available: 0:0") as info:
            choose_device(spec)
        assert spec in str(info.value)
        assert isinstance(info.value, SwarmposeError)
    if not any(d.kind == "gpu" for d in list_devices()):
        with pytest.raises(DeviceError, match="no OpenCL GPU"):
            choose_device("gpu")


def test_no_platform_says_how_to_get_one(monkeypatch):
    def none():
        raise cl.LogicError("clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR")

    monkeypatch.setattr(cl, "get_platforms", none)
    with pytest.raises(DeviceError, match="pocl-binary-distribution"):
        choose_device("cpu")


def test_sources_and_options():
    src = read_source("score.cl")
    assert "__kernel" in src and "raster_triangle" in src and '#include "' not in src
    assert define_options({"TW": 64, "CULL": True, "Z": 0.5}) == ("-D", "CULL=1", "-D", "TW=64", "-D", "Z=0.5f")
    with pytest.raises(KernelBuildError, match="no_such.cl"):
        read_source("no_such.cl")


def test_build_is_memoised_per_context_bounded_and_failures_carry_the_log():
    ctx = ClContext(choose_device("cpu"))
    assert ClContext.for_spec("cpu") is ClContext.for_spec("cpu") and ClContext.for_spec("cpu") is not ctx
    sizes = {"NV": 3, "NF": 1, "NB": 1, "TW": 8, "TH": 8, "WG": 1, "ZATOMIC": 0, "CULL": 1, "ZNEAR": 0.05,
             "WRITE_TILES": 0}
    prg = ctx.program("score.cl", sizes)
    assert ctx.program("score.cl", dict(sizes)) is prg
    assert ctx.program("score.cl", {**sizes, "TW": 9}) is not prg
    assert ClContext(ctx.device).program("score.cl", sizes) is not prg  # another context builds its own
    with pytest.raises(KernelBuildError) as info:
        ctx.program("score.cl", {**sizes, "WG": 4})  # WG > 1 without ZATOMIC: #error
    err = info.value
    assert err.filename == "score.cl" and "WG=4" in err.options
    assert "ZATOMIC" in err.log and err.device in str(err)


@pytest.mark.slow
def test_the_program_cache_is_bounded():
    ctx = ClContext(choose_device("cpu"))
    sizes = {"NV": 3, "NF": 1, "NB": 1, "TW": 8, "TH": 8, "WG": 1, "ZATOMIC": 0, "CULL": 1, "ZNEAR": 0.05,
             "WRITE_TILES": 0}
    first = ctx.program("score.cl", sizes)
    for tw in range(9, 9 + MAX_PROGRAMS):
        ctx.program("score.cl", {**sizes, "TW": tw})
    assert len(ctx._programs) == MAX_PROGRAMS
    assert ctx.program("score.cl", sizes) is not first  # the oldest was dropped and is built again


def test_pocl_threads_pinned_only_where_every_cpu_is_allowed(monkeypatch):
    """POCL_AFFINITY=1 is set where this process may run on CPUs 0..N-1 (PoCL pins thread i to
    CPU i and aborts where that is refused), never over the user's own setting."""
    monkeypatch.setattr(os, "cpu_count", lambda: 4)
    monkeypatch.delenv("POCL_AFFINITY", raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {2, 3})  # a container limited to CPUs 2-3
    assert not context.pin_pocl_threads() and "POCL_AFFINITY" not in os.environ
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2, 3})
    assert context.pin_pocl_threads() and os.environ["POCL_AFFINITY"] == "1"
    monkeypatch.setenv("POCL_AFFINITY", "0")
    assert not context.pin_pocl_threads() and os.environ["POCL_AFFINITY"] == "0"
