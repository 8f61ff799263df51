"""A small site, a state with a controllable clock, and a test client over them."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from bevflow.site import Site, parse_site

from bevflow_services.gateway import GatewayState, create_app
from tests.services.gateway.feed import SITE_YAML, FakeClock


@pytest.fixture
def site() -> Site:
    return parse_site(SITE_YAML)


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


@pytest.fixture
def state(site: Site, clock: FakeClock) -> GatewayState:
    return GatewayState(site, clock=clock, camera_timeout_s=5.0)


@pytest.fixture
def client(site: Site, state: GatewayState) -> Iterator[TestClient]:
    with TestClient(create_app(site, state)) as test_client:
        yield test_client
