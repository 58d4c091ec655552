"""The command line imports lazily: building its parser (``swarmpose --help``, ``swarmpose CMD --help``)
loads none of the heavy libraries; each command imports what it runs when it runs."""

from __future__ import annotations

import json
import subprocess
import sys

HEAVY = ("open3d", "scipy", "onnxruntime", "pyopencl", "zenoh", "jsonschema", "cv2", "trimesh", "matplotlib",
         "rerun")
COMMANDS = ("synth", "demo", "track", "eval", "serve", "replay", "health", "subscribe", "probe", "bench", "body",
            "personalize", "view")


def test_building_the_parser_imports_no_heavy_library():
    code = ("import json, sys\n"
            "import swarmpose.cli.main\n"
            "swarmpose.cli.main.build_parser()\n"
            f"print(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == []


def test_help_lists_the_commands():
    proc = subprocess.run([sys.executable, "-m", "swarmpose", "--help"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    for command in COMMANDS:
        assert command in proc.stdout, command


def test_a_warm_serve_loads_neither_scipy_spatial_nor_optimize(wave_sequence, tmp_path):
    """Importing scipy.spatial (k-d trees, Qhull) or scipy.optimize costs a start 0.2-0.5 s each: a
    single person's serve, its recording (the BVH's angles included) and a warm cache need neither."""
    code = ("import json, sys\n"
            "from swarmpose.cli.main import main\n"
            f"rc = main(['serve', {str(wave_sequence)!r}, '--zenoh-mode', 'off', '--record', sys.argv[1],"
            " '--no-overlay', '--no-ros-bag', '--frames', '3', '--quiet'])\n"
            "print(json.dumps([rc, sorted(m for m in ('scipy.spatial', 'scipy.optimize') if m in sys.modules)]))\n")
    for run in ("cold", "warm"):  # the first run fills the cache (the body's rest angles, its levels of detail)
        proc = subprocess.run([sys.executable, "-c", code, str(tmp_path / run)], capture_output=True, text=True,
                              timeout=300)
        assert proc.returncode == 0, proc.stderr
    rc, loaded = json.loads(proc.stdout.strip().splitlines()[-1])
    assert rc == 0 and (tmp_path / "warm" / "poses.bvh").is_file()
    assert loaded == []
