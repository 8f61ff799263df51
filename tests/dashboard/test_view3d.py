"""The real 3D view through the gateway in chromium: viser's page loads from /view3d/ under the
gateway's security headers, and its websocket connects through the gateway's relay."""

from __future__ import annotations

import time

from bevflow_services.gateway import create_app
from bevflow_services.launcher import free_port

from tests.dashboard.cdp import Chromium
from tests.dashboard.conftest import DASHBOARD_DIR, LiveGateway
from tests.dashboard.server import serve


def test_the_3d_view_runs_through_the_gateway(chromium: Chromium, gateway: LiveGateway) -> None:
    app = create_app(gateway.scene.site, gateway.scene.state, dashboard_dir=DASHBOARD_DIR, view3d_port=free_port())
    with serve(app) as port:
        page = chromium.new_page()
        try:
            page.goto(f"http://127.0.0.1:{port}/view3d/")
            page.wait_for("document.querySelector('canvas') !== null", timeout_s=20, what="viser's canvas")
            audit = app.state.access.store  # access control off: the relay audits as 'local'
            deadline = time.monotonic() + 20.0
            while not audit.audit_log(user="local")[1] and time.monotonic() < deadline:
                time.sleep(0.1)
            assert [e.action for e in audit.audit_log(user="local")[0]] == ["live_tracks"]  # its websocket connected
            assert not [e for e in page.errors() if "Content Security Policy" in e or "Refused" in e], page.errors()
        finally:
            page.close()
