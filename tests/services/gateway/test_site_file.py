"""The site file the gateway is given for its ``--site`` value."""

from __future__ import annotations

from pathlib import Path

from bevflow_services.gateway.site_file import site_file_of
from tests.services.gateway.calibration_site import SITE_YAML


def test_site_file_of(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text(SITE_YAML)
    assert site_file_of(path) == path.resolve()
    assert site_file_of("demo-hall") is None
