"""The gateway's OpenAPI document, as committed in ``docs/openapi.json``.

The spec does not depend on the site served, so it is built over a one-camera placeholder site.
Regenerate the committed file with ``python scripts/export_openapi.py``; a test fails when it is
out of date.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from bevflow.site import CameraConfig, Intrinsics, Pose, Site

from bevflow_services.gateway.app import create_app
from bevflow_services.gateway.state import GatewayState

SPEC_PATH = Path(__file__).resolve().parents[3] / "docs" / "openapi.json"
EXPORT_COMMAND = "python scripts/export_openapi.py"


def placeholder_site() -> Site:
    camera = CameraConfig(
        id="cam",
        image_size=(640, 640),
        intrinsics=Intrinsics(fx=200.0, fy=200.0, cx=320.0, cy=320.0),
        pose=Pose(position=(0.0, 0.0, 4.0)),
    )
    return Site(site="site", cameras=[camera])


def build_spec() -> dict[str, Any]:
    site = placeholder_site()
    return create_app(site, GatewayState(site)).openapi()


def render_spec() -> str:
    """The spec as the committed file holds it: indented JSON with a final newline."""
    return json.dumps(build_spec(), indent=2, ensure_ascii=False) + "\n"
