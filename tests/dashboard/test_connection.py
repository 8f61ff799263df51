"""What the dashboard does around the gateway: the 3D view's link and panel, and a gateway restart
(banner while it is gone, websockets reconnected and the feed caught up once it is back)."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from bevflow.schemas import OverCapacity

from bevflow_services.gateway import create_app
from bevflow_services.launcher import free_port

from tests.dashboard.cdp import Chromium, Page
from tests.dashboard.conftest import DASHBOARD_DIR, LiveGateway, alert_node, open_dashboard
from tests.dashboard.scene import Feeder, Scene
from tests.dashboard.server import serve

BANNER_HIDDEN = "document.getElementById('connection-banner').hidden"


class _Viewer(BaseHTTPRequestHandler):
    def do_GET(self) -> None:  # noqa: N802 (http.server's naming)
        body = b"<!doctype html><title>3D</title><body style='background:#222;color:#eee'>3D view</body>"
        self.send_response(200)
        self.send_header("Content-Type", "text/html")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args: object) -> None:
        pass


@contextmanager
def stand_in_3d_view() -> Iterator[int]:
    """A page where the viser server would be; yields its port."""
    server = ThreadingHTTPServer(("127.0.0.1", 0), _Viewer)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield server.server_address[1]
    finally:
        server.shutdown()
        server.server_close()


def test_3d_view_is_off_when_the_gateway_runs_none(page: Page) -> None:
    assert page.evaluate("document.getElementById('view3d-toggle').disabled") is True
    assert page.evaluate("document.getElementById('view3d-link').hidden") is True


def test_3d_view_opens_in_a_panel_and_links_to_a_new_tab(chromium: Chromium, gateway: LiveGateway) -> None:
    app = create_app(gateway.scene.site, gateway.scene.state, dashboard_dir=DASHBOARD_DIR)
    with stand_in_3d_view() as view_port, serve(app) as port:
        app.state.view3d_port = view_port  # what the lifespan sets when it starts viser
        page = open_dashboard(chromium, f"http://127.0.0.1:{port}/")
        try:
            url = f"http://127.0.0.1:{port}/view3d/"  # through the gateway, which relays viser
            page.wait_for("!document.getElementById('view3d-toggle').disabled", what="the 3D button")
            assert page.evaluate("document.getElementById('view3d-link').href") == url
            assert page.evaluate("document.getElementById('view3d-link').target") == "_blank"
            assert page.evaluate("document.getElementById('view3d-frame').getAttribute('src')") is None  # not loaded until asked

            page.click("#view3d-toggle")
            page.wait_for("!document.getElementById('view3d-panel').hidden", what="the 3D panel")
            assert page.evaluate("document.getElementById('view3d-frame').src") == url
            assert page.evaluate("document.getElementById('view3d-toggle').getAttribute('aria-expanded')") == "true"

            page.click("#view3d-toggle")
            page.wait_for("document.getElementById('view3d-panel').hidden", what="the map again")
            assert page.evaluate("document.getElementById('view3d-toggle').getAttribute('aria-expanded')") == "false"
        finally:
            page.close()


def test_banner_while_the_gateway_is_gone_then_live_again_after_a_restart(chromium: Chromium) -> None:
    port = free_port()
    url = f"http://127.0.0.1:{port}/"
    first = Scene.build()
    first.state.apply(OverCapacity(id="oc-forgotten", start_ns=time.time_ns(), zone="gate-a", capacity=15, peak=16))
    with Feeder(first), serve(create_app(first.site, first.state, dashboard_dir=DASHBOARD_DIR), port):
        page = open_dashboard(chromium, url)
        assert page.evaluate(BANNER_HIDDEN) is True
        page.wait_for(f"{alert_node('oc-forgotten')}?.dataset.active === 'true'", what="the alert before the restart")
    try:
        page.wait_for(f"!{BANNER_HIDDEN}", timeout_s=5, what="the connection-lost banner")
        assert "Reconnecting" in page.evaluate("document.getElementById('connection-detail').textContent")
        assert page.evaluate("document.getElementById('system-status').dataset.status") == "down"
        assert page.evaluate("document.body.dataset.connection") == "lost"

        # The gateway comes back (a new process: new state), with an alert that began meanwhile.
        second = Scene.build()
        second.state.apply(OverCapacity(id="oc-while-away", start_ns=time.time_ns(), zone="gate-a", capacity=15, peak=16))
        with Feeder(second), serve(create_app(second.site, second.state, dashboard_dir=DASHBOARD_DIR), port):
            page.wait_for(BANNER_HIDDEN, timeout_s=15, what="the banner to go once reconnected")
            page.wait_for(alert_node("oc-while-away"), timeout_s=5, what="the alert raised while away")
            # The restarted gateway no longer knows the first one's alert: it is not shown as ongoing.
            page.wait_for(f"{alert_node('oc-forgotten')}.dataset.active === 'false'", what="the forgotten alert")
            assert "no longer reported" in page.evaluate(f"{alert_node('oc-forgotten')}.textContent")
            assert page.evaluate(f"{alert_node('inc-1-2')}.dataset.active") == "true"  # known to both
            time_before = page.evaluate("document.getElementById('clock').textContent")
            page.wait_for(f"document.getElementById('clock').textContent !== {time_before!r}", timeout_s=5, what="live ticks")
    finally:
        page.close()
