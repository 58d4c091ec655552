"""Service configuration: defaults < TOML file < SWARMPOSE_* environment < flags, and clear errors."""

from __future__ import annotations

import subprocess
import sys

import pytest

from swarmpose.cli.settings import ENV_CONFIG, ENV_PREFIX, environment_names, from_environment, load, read_toml
from swarmpose.core.errors import ConfigError
from swarmpose.core.settings import default_of, format_value, leaves
from swarmpose.pipeline.config import ServiceConfig


def test_each_layer_overrides_the_one_below(tmp_path):
    conf = tmp_path / "swarmpose.toml"
    conf.write_text('source = "folder:/a"\ncamera-id = "from_file"\nparticles = 32\nconnect = ["tcp/1.2.3.4:7447"]\n'
                    'multicast = false\n')
    env = {"SWARMPOSE_CAMERA_ID": "from_env", "SWARMPOSE_GENERATIONS": "16", "SWARMPOSE_PARTICLES": "48"}
    c = load(ServiceConfig, {"particles": 8, "generations": None}, config_file=str(conf), env=env)
    assert c.source == "folder:/a"            # file over default
    assert c.camera_id == "from_env"          # env over file
    assert c.tracker.generations == 16        # env over default, flag None = not given
    assert c.tracker.particles == 8           # flag over env over file
    assert c.zenoh.connect == ("tcp/1.2.3.4:7447",) and c.zenoh.multicast is False
    assert c.tracker.mode == ServiceConfig().tracker.mode == "hybrid"
    assert load(ServiceConfig, {}, env={ENV_CONFIG: str(conf)}).camera_id == "from_file"
    assert load(ServiceConfig, {}, env={}, defaults={"zenoh_mode": "off"}).zenoh.zenoh_mode == "off"
    assert load(ServiceConfig, {}, env={"SWARMPOSE_ZENOH_MODE": "client"},
                defaults={"zenoh_mode": "off"}).zenoh.zenoh_mode == "client"


def test_a_file_may_group_settings_in_section_tables_and_use_older_names(tmp_path):
    conf = tmp_path / "swarmpose.toml"
    conf.write_text('joints = "openpose-json:/j"\nmax-frames = 5\n[tracker]\nparticles = 16\ntile = [32, 48]\n'
                    '[zenoh]\nzenoh_mode = "client"\n')
    c = load(ServiceConfig, {}, config_file=str(conf), env={})
    assert c.detector == "openpose-json:/j" and c.frames == 5
    assert c.tracker.particles == 16 and c.tracker.tile == (32, 48) and c.zenoh.zenoh_mode == "client"


def test_environment_values_are_converted_by_field_type():
    env = {"SWARMPOSE_CONNECT": "tcp/a:1, tcp/b:2", "SWARMPOSE_LOOP": "yes", "SWARMPOSE_MULTICAST": "0",
           "SWARMPOSE_RATE": "12.5", "SWARMPOSE_MAX_FRAMES": "7", "SWARMPOSE_TILE": "32x48",
           "SWARMPOSE_UNRELATED": "x"}
    assert from_environment(env, ServiceConfig) == {"connect": ("tcp/a:1", "tcp/b:2"), "loop": True,
                                                    "multicast": False, "rate": 12.5, "frames": 7, "tile": (32, 48)}
    # every setting has its variable, and each default written as text reads back as itself
    settings = {name: default_of(f) for name, (_, f) in leaves(ServiceConfig).items()
                if name not in ("connect", "listen")}
    env = {f"{ENV_PREFIX}{n.upper()}": "" if v == "" else format_value(v) for n, v in settings.items()}
    assert from_environment(env, ServiceConfig) == settings


def test_older_variable_names_are_aliases_and_the_current_name_wins():
    names = environment_names(ServiceConfig)
    assert names["SWARMPOSE_JOINTS"] == names["SWARMPOSE_DETECTOR"] == "detector"
    assert names["SWARMPOSE_MAX_FRAMES"] == names["SWARMPOSE_FRAMES"] == "frames"
    assert names["SWARMPOSE_CL_DEVICE"] == names["SWARMPOSE_DEVICE"] == "device"
    assert set(names.values()) == set(leaves(ServiceConfig))
    assert from_environment({"SWARMPOSE_JOINTS": "onnx:m.onnx", "SWARMPOSE_CL_DEVICE": "cpu"}, ServiceConfig) == \
        {"detector": "onnx:m.onnx", "device": "cpu"}
    both = {"SWARMPOSE_CL_DEVICE": "cpu", "SWARMPOSE_DEVICE": "gpu"}
    assert load(ServiceConfig, {}, env=both).tracker.device == "gpu"


@pytest.mark.parametrize(("env", "needle"), [
    ({"SWARMPOSE_MULTICAST": "maybe"}, "SWARMPOSE_MULTICAST"),
    ({"SWARMPOSE_PARTICLES": "many"}, "SWARMPOSE_PARTICLES"),
    ({"SWARMPOSE_CAMERA_ID": "cam/0"}, "SWARMPOSE_CAMERA_ID: camera id 'cam/0'"),
    ({"SWARMPOSE_TILE": "64by64"}, "SWARMPOSE_TILE: tile must be WxH"),
    ({"SWARMPOSE_ZENOH_MODE": "router"}, "SWARMPOSE_ZENOH_MODE: zenoh_mode must be one of"),
    ({"SWARMPOSE_RATE": "-1"}, "SWARMPOSE_RATE: rate must be at least 0"),
    ({"SWARMPOSE_STATUS_PERIOD_S": "inf"}, "SWARMPOSE_STATUS_PERIOD_S: status_period_s must be a finite"),
    ({"SWARMPOSE_REOPEN_S": "nan"}, "SWARMPOSE_REOPEN_S: reopen_s must be a finite"),
    ({"SWARMPOSE_PARTICLES": "0"}, "SWARMPOSE_PARTICLES: particles must be at least 1"),
])
def test_bad_values_name_the_variable_and_what_is_allowed(env, needle):
    with pytest.raises(ConfigError, match=needle.replace("(", r"\(")):
        load(ServiceConfig, {}, env=env)


def test_bad_files_name_the_file_and_the_key(tmp_path):
    with pytest.raises(ConfigError, match="does not exist"):
        read_toml(tmp_path / "missing.toml", ServiceConfig)
    broken = tmp_path / "broken.toml"
    broken.write_text("source = \n")
    with pytest.raises(ConfigError, match=r"broken.toml is not valid TOML"):
        read_toml(broken, ServiceConfig)
    unknown = tmp_path / "unknown.toml"
    unknown.write_text('[swarmpose]\nsorce = "folder:/a"\n')
    with pytest.raises(ConfigError, match=r"unknown key 'sorce'; keys are .*source"):
        read_toml(unknown, ServiceConfig)
    typed = tmp_path / "typed.toml"
    typed.write_text('particles = "64"\nconnect = "tcp/a:1"\n')
    assert read_toml(typed, ServiceConfig) == {"particles": 64, "connect": ("tcp/a:1",)}
    typed.write_text("particles = 6.5\n")
    with pytest.raises(ConfigError, match="particles = 6.5 is not an integer"):
        read_toml(typed, ServiceConfig)


@pytest.mark.slow
def test_serve_with_a_broken_config_or_no_source_exits_2(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("camera_id = 'a b'\n")
    env = {"PATH": "", "HOME": str(tmp_path)}
    run = subprocess.run([sys.executable, "-m", "swarmpose", "serve", "--config", str(bad)],
                         capture_output=True, text=True, env=env, timeout=120)
    assert run.returncode == 2 and "camera id 'a b'" in run.stderr
    run = subprocess.run([sys.executable, "-m", "swarmpose", "serve"], capture_output=True, text=True, env=env,
                         timeout=120)
    assert run.returncode == 2 and "no source" in run.stderr and "SWARMPOSE_SOURCE" in run.stderr


def test_a_file_merges_the_top_level_and_the_swarmpose_table_with_their_sections(tmp_path):
    conf = tmp_path / "both.toml"
    conf.write_text('[tracker]\nparticles = 16\n[zenoh]\nzenoh_mode = "client"\n'
                    '[swarmpose]\nsource = "folder:/a"\n[swarmpose.tracker]\ngenerations = 8\n'
                    '[swarmpose.zenoh]\nmulticast = false\n')
    assert read_toml(conf, ServiceConfig) == {"particles": 16, "zenoh_mode": "client", "source": "folder:/a",
                                              "generations": 8, "multicast": False}
    c = load(ServiceConfig, {}, config_file=str(conf), env={})
    assert (c.tracker.particles, c.tracker.generations, c.zenoh.zenoh_mode) == (16, 8, "client")


@pytest.mark.parametrize(("text", "needle"), [
    ('particles = 8\n[swarmpose]\nparticles = 16\n', r"particles is given twice \('particles' at the top level and "
                                                     r"'particles' in \[swarmpose\]\)"),
    ('[tracker]\nparticles = 8\n[swarmpose.tracker]\nparticles = 16\n', r"particles is given twice"),
    ('joints = "simulated"\n[swarmpose]\ndetector = "simulated"\n', r"detector is given twice \('joints'"),
    ('[zenoh]\nparticles = 3\n', r"key 'particles' in table \[zenoh\] is not a zenoh setting; it belongs in "
                                 r"\[tracker\]"),
    ('[swarmpose.tracker]\nzenoh-mode = "off"\n', r"key 'zenoh-mode' in table \[swarmpose.tracker\] is not a "
                                                  r"tracker setting; it belongs in \[swarmpose.zenoh\]"),
    ('[tracker]\nsource = "folder:/a"\n', r"key 'source' in table \[tracker\] .* belongs at the top level"),
])
def test_a_setting_given_twice_or_in_a_table_not_its_own_names_the_file_and_key(tmp_path, text, needle):
    conf = tmp_path / "clash.toml"
    conf.write_text(text)
    with pytest.raises(ConfigError, match=r"config file .*clash.toml: " + needle):
        read_toml(conf, ServiceConfig)
