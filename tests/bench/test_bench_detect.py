"""``swarmpose bench detect``: runs, reports every detector, and its errors agree with the oracle tests."""

from __future__ import annotations

import json

from conftest import BLAZEPOSE_COCO_BOUND_PX, MOVENET_COCO_BOUND_PX, needs_assets

from swarmpose.bench.detect import format_detect_bench
from swarmpose.cli.main import main


@needs_assets
def test_bench_detect_json(capsys):
    assert main(["bench", "detect", "--repeats", "1", "--json", "--threads", "1"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["repeats"] == 1 and result["threads"] == 1
    assert set(result["detectors"]) == {"movenet", "blazepose"}
    for row in result["detectors"].values():
        assert set(row) == {"model", "layout", "coco_ms", "vga_ms", "coco_median_error_px", "coco_crop"}
        assert row["coco_ms"] > 0 and row["vga_ms"] > 0
    assert result["detectors"]["movenet"]["layout"] == "coco17"
    assert result["detectors"]["blazepose"]["layout"] == "blazepose33"
    # the same numbers as the oracle tests in test_onnx_detectors.py measure against COCO's annotation
    assert 0 < result["detectors"]["movenet"]["coco_median_error_px"] < MOVENET_COCO_BOUND_PX
    assert 0 < result["detectors"]["blazepose"]["coco_median_error_px"] < BLAZEPOSE_COCO_BOUND_PX
    text = format_detect_bench(result)
    assert "movenet" in text and "blazepose" in text and "COCO median error" in text


def test_bench_detect_without_assets_says_where_it_looked(tmp_path, capsys):
    assert main(["bench", "detect", "--repeats", "1", "--assets", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert str(tmp_path) in err and "--assets" in err
