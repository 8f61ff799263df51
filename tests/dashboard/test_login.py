"""The login page in a real browser, on a gateway with access control on: the dashboard sends an
anonymous visitor to it, a wrong password shows an error, the right one lands on the live dashboard,
and the first-run setup link creates the first admin."""

from __future__ import annotations

import json
from collections.abc import Iterator

import pytest

from bevflow_services.gateway import create_app
from tests.dashboard.cdp import Chromium, Page
from tests.dashboard.conftest import DASHBOARD_DIR
from tests.dashboard.scene import Feeder, Scene
from tests.dashboard.server import serve
from tests.services.gateway.access import PASSWORD, secured_access


@pytest.fixture(scope="module")
def secured_gateway() -> Iterator[tuple[str, object]]:
    scene = Scene.build()
    access, _ = secured_access()
    app = create_app(scene.site, scene.state, dashboard_dir=DASHBOARD_DIR, access=access)
    with Feeder(scene), serve(app) as port:
        yield f"http://127.0.0.1:{port}", access


@pytest.fixture
def tab(chromium: Chromium) -> Iterator[Page]:
    page = chromium.new_page()
    try:
        yield page
    finally:
        page.close()


def fill(page: Page, form: str, **values: str) -> None:
    for field, value in values.items():
        page.evaluate(f"document.querySelector('#{form} [name={field}]').value = {json.dumps(value)}")
    page.click(f"#{form} button[type=submit]")


def test_a_wrong_password_shows_an_error_and_the_right_one_opens_the_dashboard(tab: Page, secured_gateway) -> None:
    base, _ = secured_gateway
    tab.goto(f"{base}/")
    tab.wait_for("document.body.dataset.ready === 'true' && location.pathname === '/login.html'", what="the login page")
    assert tab.evaluate("new URLSearchParams(location.search).get('next')") == "/"

    fill(tab, "login-form", name="operator", password="not the password")
    error = tab.wait_for("!document.getElementById('login-error').hidden && document.getElementById('login-error').textContent",
                         what="the error message")
    assert error == "Wrong user name or password."
    assert tab.evaluate("location.pathname") == "/login.html"

    fill(tab, "login-form", name="operator", password=PASSWORD)
    tab.wait_for("location.pathname === '/' && window.bevflow && window.bevflow.ready && window.bevflow.people > 0",
                 timeout_s=15, what="the live dashboard")
    assert tab.evaluate("fetch('/api/auth/me').then((r) => r.json()).then((me) => me.name)") == "operator"


def test_the_setup_link_creates_the_first_admin(tab: Page, secured_gateway) -> None:
    base, access = secured_gateway
    saved = [(u.name, u.role, u.password_hash, u.created_ns) for u in access.store.users()]
    for name, *_ in saved:
        access.store.remove_user(name)
    try:
        token = access.prepare_setup()
        tab.goto(f"{base}/login.html#setup={token}")
        tab.wait_for("document.body.dataset.ready === 'true'", what="the setup page")
        assert tab.evaluate("document.getElementById('login-form').hidden") is True
        fill(tab, "setup-form", name="chief", password="a long password", again="another password")
        assert tab.wait_for("document.getElementById('setup-error').textContent", what="the mismatch") == "The two passwords differ."
        fill(tab, "setup-form", name="chief", password="a long password", again="a long password")
        tab.wait_for("location.pathname === '/' && window.bevflow && window.bevflow.ready", timeout_s=15, what="the dashboard")
        assert [(u.name, u.role) for u in access.store.users()] == [("chief", "admin")]
    finally:
        access.store.remove_user("chief") if access.store.user("chief") else None
        for name, role, password_hash, created_ns in saved:
            access.store.add_user(name, role, password_hash, created_ns)


def log_in(tab: Page, base: str, name: str) -> None:
    tab.goto(f"{base}/login.html")
    tab.wait_for("document.body.dataset.ready === 'true'", what="the login page")
    fill(tab, "login-form", name=name, password=PASSWORD)
    tab.wait_for("location.pathname === '/' && window.bevflow && window.bevflow.ready && window.bevflow.alerts > 0",
                 timeout_s=15, what="the live dashboard")


@pytest.mark.parametrize(
    ("name", "acknowledge_shown", "calibration_shown"),
    [("viewer", False, False), ("operator", True, False), ("admin", True, True)],
)
def test_the_dashboard_shows_who_is_logged_in_and_offers_only_what_their_role_may_do(
    tab: Page, secured_gateway, name: str, acknowledge_shown: bool, calibration_shown: bool
) -> None:
    base, _ = secured_gateway
    log_in(tab, base, name)
    assert tab.evaluate("document.getElementById('session').hidden") is False
    assert tab.evaluate("document.querySelector('#session .session-name').textContent") == f"{name} · {name}"
    shown = "(b) => b.offsetParent !== null"
    assert tab.evaluate(f"[...document.querySelectorAll('.ack-button')].some({shown})") is acknowledge_shown
    assert tab.evaluate("!document.getElementById('calibration-link').hidden") is calibration_shown
    tab.click("#logout")
    tab.wait_for("location.pathname === '/login.html' && document.body.dataset.ready === 'true'", what="the login page")
    assert tab.evaluate("fetch('/api/auth/me').then((r) => r.status)") == 401


def test_an_ended_session_sends_the_dashboard_back_to_the_login_page(tab: Page, secured_gateway) -> None:
    base, _ = secured_gateway
    log_in(tab, base, "viewer")
    tab.evaluate("fetch('/api/auth/logout', {method: 'POST'}).then((r) => r.status)")  # as if it expired
    tab.wait_for("location.pathname === '/login.html'", timeout_s=10, what="the login page")
    assert tab.evaluate("new URLSearchParams(location.search).get('next')") == "/"
