"""Service configuration: defaults < TOML file < SWARMPOSE_* environment < flags, and clear errors."""

from __future__ import annotations

import subprocess
import sys

import pytest
from swarmpose.config import FIELDS, ServiceConfig, from_environment, load_config, read_toml
from swarmpose.errors import ConfigError


def test_each_layer_overrides_the_one_below(tmp_path):
    conf = tmp_path / "swarmpose.toml"
    conf.write_text('source = "folder:/a"\ncamera-id = "from_file"\nparticles = 32\nconnect = ["tcp/1.2.3.4:7447"]\n'
                    'multicast = false\n')
    env = {"SWARMPOSE_CAMERA_ID": "from_env", "SWARMPOSE_GENERATIONS": "16", "SWARMPOSE_PARTICLES": "48"}
    c = load_config({"particles": 8, "generations": None}, config_file=str(conf), env=env)
    assert c.source == "folder:/a"            # file over default
    assert c.camera_id == "from_env"          # env over file
    assert c.generations == 16                # env over default, flag None = not given
    assert c.particles == 8                   # flag over env over file
    assert c.connect == ("tcp/1.2.3.4:7447",) and c.multicast is False
    assert c.mode == ServiceConfig().mode == "hybrid"
    assert load_config({}, env={"SWARMPOSE_CONFIG": str(conf)}).camera_id == "from_file"
    assert load_config({}, env={}, defaults={"zenoh_mode": "off"}).zenoh_mode == "off"
    assert load_config({}, env={"SWARMPOSE_ZENOH_MODE": "client"}, defaults={"zenoh_mode": "off"}).zenoh_mode == \
        "client"


def test_environment_values_are_converted_by_field_type():
    env = {"SWARMPOSE_CONNECT": "tcp/a:1, tcp/b:2", "SWARMPOSE_LOOP": "yes", "SWARMPOSE_MULTICAST": "0",
           "SWARMPOSE_RATE": "12.5", "SWARMPOSE_MAX_FRAMES": "7", "SWARMPOSE_UNRELATED": "x"}
    assert from_environment(env) == {"connect": ("tcp/a:1", "tcp/b:2"), "loop": True, "multicast": False,
                                     "rate": 12.5, "max_frames": 7}
    assert set(from_environment({f"SWARMPOSE_{n.upper()}": str(getattr(ServiceConfig(), n)).strip("()")
                                 for n in FIELDS if n not in ("connect", "listen")})) == set(FIELDS) - {"connect",
                                                                                                         "listen"}


@pytest.mark.parametrize(("env", "needle"), [
    ({"SWARMPOSE_MULTICAST": "maybe"}, "SWARMPOSE_MULTICAST"),
    ({"SWARMPOSE_PARTICLES": "many"}, "SWARMPOSE_PARTICLES"),
    ({"SWARMPOSE_CAMERA_ID": "cam/0"}, "SWARMPOSE_CAMERA_ID: camera id 'cam/0'"),
    ({"SWARMPOSE_TILE": "64by64"}, "SWARMPOSE_TILE: tile must be WxH"),
    ({"SWARMPOSE_ZENOH_MODE": "router"}, "SWARMPOSE_ZENOH_MODE: zenoh_mode must be one of"),
    ({"SWARMPOSE_RATE": "-1"}, "SWARMPOSE_RATE: rate must be a finite number, 0 or more"),
    ({"SWARMPOSE_STATUS_PERIOD_S": "inf"}, "SWARMPOSE_STATUS_PERIOD_S: status_period_s must be a finite"),
    ({"SWARMPOSE_REOPEN_S": "nan"}, "SWARMPOSE_REOPEN_S: reopen_s must be a finite"),
    ({"SWARMPOSE_PARTICLES": "0"}, "SWARMPOSE_PARTICLES: particles must be at least 1"),
])
def test_bad_values_name_the_variable_and_what_is_allowed(env, needle):
    with pytest.raises(ConfigError, match=needle.replace("(", r"\(")):
        load_config({}, env=env)


def test_bad_files_name_the_file_and_the_key(tmp_path):
    with pytest.raises(ConfigError, match="does not exist"):
        read_toml(tmp_path / "missing.toml")
    broken = tmp_path / "broken.toml"
    broken.write_text("source = \n")
    with pytest.raises(ConfigError, match=r"broken.toml is not valid TOML"):
        read_toml(broken)
    unknown = tmp_path / "unknown.toml"
    unknown.write_text('[swarmpose]\nsorce = "folder:/a"\n')
    with pytest.raises(ConfigError, match=r"unknown key 'sorce'; keys are .*source"):
        read_toml(unknown)
    typed = tmp_path / "typed.toml"
    typed.write_text('particles = "64"\nconnect = "tcp/a:1"\n')
    assert read_toml(typed) == {"particles": 64, "connect": ("tcp/a:1",)}
    typed.write_text("particles = 6.5\n")
    with pytest.raises(ConfigError, match="particles = 6.5 is not an integer"):
        read_toml(typed)


def test_serve_with_a_broken_config_or_no_source_exits_2(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("camera_id = 'a b'\n")
    env = {"PATH": "", "HOME": str(tmp_path)}
    run = subprocess.run([sys.executable, "-m", "swarmpose.cli", "serve", "--config", str(bad)],
                         capture_output=True, text=True, env=env, timeout=120)
    assert run.returncode == 2 and "camera id 'a b'" in run.stderr
    run = subprocess.run([sys.executable, "-m", "swarmpose.cli", "serve"], capture_output=True, text=True, env=env,
                         timeout=120)
    assert run.returncode == 2 and "no source" in run.stderr and "SWARMPOSE_SOURCE" in run.stderr
