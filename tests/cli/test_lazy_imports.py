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
