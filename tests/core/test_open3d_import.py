"""Open3D without its Plotly/Dash viewer at import (swarmpose.core.open3d_import)."""

from __future__ import annotations

import subprocess
import sys
import textwrap


def run_fresh(code: str) -> str:
    """stdout of ``code`` run in a new interpreter (a process whose open3d is not imported yet)."""
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_open3d_comes_without_dash_and_its_viewer_still_works_when_called():
    out = run_fresh("""
        import sys
        import numpy as np
        from swarmpose.core.open3d_import import open3d
        o3d = open3d()
        before = "dash" in sys.modules
        scene = o3d.t.geometry.RaycastingScene()  # the part swarmpose uses works as usual
        scene.add_triangles(o3d.core.Tensor(np.array([[0, 0, 1], [1, 0, 1], [0, 1, 1]], np.float32)),
                            o3d.core.Tensor(np.array([[0, 1, 2]], np.uint32)))
        hit = scene.cast_rays(o3d.core.Tensor(np.array([[0, 0, 0, 0.2, 0.2, 1]], np.float32)))["t_hit"].numpy()[0]
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.random.default_rng(0).random((20, 3))))
        figure = o3d.visualization.get_plotly_fig([cloud])
        print(before, round(float(hit), 4), "dash" in sys.modules, type(figure).__name__, len(figure.data))
    """)
    assert out == "False 1.0 True Figure 1"


def test_open3d_imported_before_is_left_alone():
    out = run_fresh("""
        import sys
        import open3d as first
        from swarmpose.core.open3d_import import VIEWER, open3d
        print(open3d() is first, getattr(sys.modules[VIEWER], "__swarmpose_stand_in__", False))
    """)
    assert out == "True False"
