"""``bevflow plan``: the printed layout, the site file it writes and the coverage map."""

from __future__ import annotations

from pathlib import Path

import cv2
import pytest

from bevflow.site import load_site
from bevflow_services.cli import main


def test_plan_writes_a_site_and_a_map(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    site_path, png = tmp_path / "hall.yaml", tmp_path / "hall.png"
    rc = main(["plan", "--width", "40", "--depth", "25", "--ceiling", "5.5", "--lens-fov", "185", "--name", "hall",
               "--out", str(site_path), "--png", str(png)])
    assert rc == 0
    out = capsys.readouterr().out
    assert "3 x 3 = 9 cameras" in out and "monitored radius per camera: 8 m" in out
    assert "cam-1-1" in out and "next:" in out and f"--site {site_path}" in out
    site = load_site(site_path)
    assert site.site == "hall" and len(site.cameras) == 9 and site.floor == (0.0, 0.0, 40.0, 25.0)
    assert site_path.read_text().startswith("# Planned with: bevflow plan --width 40 --depth 25 --ceiling 5.5")
    image = cv2.imread(str(png))
    assert image is not None and image.shape[1] > image.shape[0] > 300


def test_plan_only_prints_without_out(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["plan", "--width", "12", "--depth", "6", "--ceiling", "3.3"]) == 0
    out = capsys.readouterr().out
    assert "layout:" in out and "--out site.yaml" in out and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--ceiling", "2"], "3 to 10 m"),
        (["--ceiling", "5", "--width", "-3"], "positive width"),
        (["--ceiling", "5", "--image-size", "big"], "--image-size"),
        (["--ceiling", "5", "--name", "my hall"], "--name"),
        (["--ceiling", "5", "--out", "{existing}"], "exists"),
        (["--ceiling", "5", "--png", "{dir}/map.gif"], ".png"),
        (["--ceiling", "5", "--overlap", "30"], "whole circle"),
    ],
)
def test_bad_input_is_one_line(extra: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    existing = tmp_path / "site.yaml"
    existing.write_text("keep me")
    extra = [e.format(existing=existing, dir=tmp_path) for e in extra]
    args = ["plan", "--width", "20", "--depth", "10", *extra]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert existing.read_text() == "keep me"
