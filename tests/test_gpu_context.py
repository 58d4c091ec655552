"""Device choice and kernel building (swarmpose.gpu.context / program) on PoCL's CPU device."""

from __future__ import annotations

import pyopencl as cl
import pytest
from swarmpose.errors import SwarmposeError
from swarmpose.gpu.context import ENV_DEVICE, choose_device, device_context, list_devices
from swarmpose.gpu.errors import DeviceError, KernelBuildError
from swarmpose.gpu.program import build_program, define_options, read_source


def test_device_specs(monkeypatch):
    monkeypatch.delenv(ENV_DEVICE, raising=False)
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
    monkeypatch.setenv(ENV_DEVICE, f"{first.platform_index}:{first.device_index}")
    assert choose_device(None).name.strip() == first.name


def test_unknown_devices_list_what_exists(monkeypatch):
    monkeypatch.delenv(ENV_DEVICE, raising=False)
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


def test_build_is_memoised_and_failures_carry_the_log():
    ctx, _ = device_context(choose_device("cpu"))
    sizes = {"NV": 3, "NF": 1, "NB": 1, "TW": 8, "TH": 8, "WG": 1, "ZATOMIC": 0, "CULL": 1, "ZNEAR": 0.05,
             "WRITE_TILES": 0}
    prg = build_program(ctx, "score.cl", sizes)
    assert build_program(ctx, "score.cl", dict(sizes)) is prg
    assert build_program(ctx, "score.cl", {**sizes, "TW": 9}) is not prg
    with pytest.raises(KernelBuildError) as info:
        build_program(ctx, "score.cl", {**sizes, "WG": 4})  # WG > 1 without ZATOMIC: #error
    err = info.value
    assert err.filename == "score.cl" and "WG=4" in err.options
    assert "ZATOMIC" in err.log and err.device in str(err)
