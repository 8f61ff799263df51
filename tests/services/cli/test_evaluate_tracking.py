from __future__ import annotations

import json
from pathlib import Path

import pytest

from bevflow_services.cli import main
from tests.bevflow.datasets.test_wildtrack import write_fake_wildtrack

TRACKING = {"MOTA", "IDF1", "IDSW", "MT", "ML", "FRAG"}


@pytest.fixture(scope="module")
def root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_fake_wildtrack(tmp_path_factory.mktemp("cli-tracking") / "wildtrack")


def test_wildtrack_reports_tracking_scores_next_to_detection(root: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "tracked.json"
    assert main(["evaluate", "--dataset", "wildtrack", "--root", str(root), "--no-truncation", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert TRACKING <= result.keys()
    # 3 people x 3 frames, all found in every frame. A track fused from both cameras is confirmed
    # on its first detection; person 9 is seen by one camera only, so their track is confirmed on
    # its 2nd detection, and their first frame is the tracked output's only miss
    assert result["MODA"] == 1.0
    assert (result["tracked"]["fn"], result["tracked"]["fp"], result["IDSW"], result["FRAG"]) == (1, 0, 0, 0)
    assert result["MOTA"] == pytest.approx(1 - 1 / 9) and result["tracked_MODA"] == pytest.approx(1 - 1 / 9)
    assert (result["MT"], result["ML"]) == (2, 0)  # person 9: 2 of 3 frames, partly tracked
    printed = capsys.readouterr().out
    assert "IDF1" in printed and "det MODA" in printed


def test_every_method_is_tracked(root: Path, tmp_path: Path) -> None:
    out = tmp_path / "all.json"
    assert main(["evaluate", "--dataset", "wildtrack", "--root", str(root), "--method", "all", "--json", str(out)]) == 0
    results = json.loads(out.read_text())
    assert [r["method"] for r in results] == ["cylinder", "bbox-center", "nearest-point"]
    assert all(TRACKING <= r.keys() for r in results)
