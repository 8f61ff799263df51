"""A property-based run of every operation in the committed OpenAPI spec (docs/openapi.json)
against a gateway holding live data: parameters drawn from their declared schemas, values just
outside them, and garbage. No request may get a 5xx, and every 4xx says what was wrong in one
readable message."""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from typing import Any
from urllib.parse import quote

import pytest
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bevflow.schemas import Occupancy, Tracks
from bevflow.site import Site, parse_site

from bevflow_services.gateway import GatewayState, create_app
from bevflow_services.gateway.history_db import DatabaseHistory
from bevflow_services.gateway.openapi import SPEC_PATH
from bevflow_services.recorder.recorder import Recorder
from bevflow_services.storage import HistoryDatabase
from tests.bevflow.test_schemas_fuzz import json_values, mutated
from tests.services.gateway.feed import SITE_YAML, S, T0, FakeClock, occupancy, over_capacity, tracks, violation

SPEC: dict[str, Any] = json.loads(SPEC_PATH.read_text(encoding="utf-8"))
OPERATIONS = sorted((path, method) for path, ops in SPEC["paths"].items() for method in ops)
EXAMPLES_PER_OPERATION = 60
USER = "ana"  # a user for the routes that name one

garbage = st.one_of(
    st.text(max_size=30),
    st.sampled_from(["", " ", "-1", "0", "1e309", "-1e309", "NaN", "inf", "-inf", "null", "true", "[]", "{}",
                     "1" * 40, "9" * 400, "0x10", "1_000", "%00", "..", "../etc/passwd", "ünïcödé", "\u202e",
                     "2024-13-45", "2024-02-30T25:61:00Z", "9999-12-31T23:59:59Z", "0001-01-01", "-9999999999",
                     "1e18", "2023-11-14T22:13:20+14:00", "Europe/Nowhere", "../../UTC", ",", ",,,"]),
)


def strategy(schema: dict[str, Any], *, past_bounds: bool = True) -> st.SearchStrategy[str | None]:
    """Query-string values for a parameter schema: valid ones, the bounds and (``past_bounds``)
    a bit past them."""
    if "anyOf" in schema:
        options = [strategy(s, past_bounds=past_bounds) for s in schema["anyOf"] if s.get("type") != "null"]
        return st.one_of(*options)
    if "enum" in schema:
        return st.sampled_from([*schema["enum"], schema["enum"][0].upper()])
    kind = schema.get("type")
    if kind == "integer":
        low, high = schema.get("minimum", -(2**40)), schema.get("maximum", 2**40)
        past = [low - 1, high + 1, 2**63, -(2**63) - 1] if past_bounds else [low, high]
        return st.one_of(st.integers(low, high), st.sampled_from(past)).map(str)
    if kind == "number":
        low = schema.get("minimum", schema.get("exclusiveMinimum", -1e12))
        high = schema.get("maximum", 1e12)
        edges = [low, high, low - 1e-9, high * 1.0001 + 1, math.nextafter(low, -math.inf)] if past_bounds else [high]
        exclusive = "exclusiveMinimum" in schema
        return st.one_of(st.floats(low, high, allow_nan=False, exclude_min=exclusive), st.sampled_from(edges)).map(repr)
    if kind == "boolean":
        return st.sampled_from(["true", "false", "1", "0", "yes", "maybe"])
    if schema.get("format") == "date-time":
        return st.one_of(st.datetimes().map(lambda d: d.isoformat() + "Z"), st.integers(-(2**40), 2**40).map(str))
    if schema.get("format") == "date":
        return st.dates().map(str)
    return st.text(max_size=schema.get("maxLength", 30))


def body(schema: dict[str, Any], depth: int = 0) -> st.SearchStrategy[Any]:
    """JSON values of the declared shape for a schema of the spec (``$ref``s resolved); past a
    few levels, any JSON value."""
    if "$ref" in schema:
        schema = SPEC["components"]["schemas"][schema["$ref"].rsplit("/", 1)[1]]
    if depth > 4:
        return json_values
    if "anyOf" in schema or "oneOf" in schema:
        shaped = st.one_of(*[body(s, depth + 1) for s in schema.get("anyOf", schema.get("oneOf"))])
    elif "enum" in schema:
        shaped = st.sampled_from(schema["enum"])
    elif schema.get("type") == "object":
        properties = schema.get("properties", {})
        required = set(schema.get("required", []))
        shaped = st.fixed_dictionaries(
            {name: body(s, depth + 1) for name, s in properties.items() if name in required},
            optional={name: body(s, depth + 1) for name, s in properties.items() if name not in required})
    elif schema.get("type") == "array" and "prefixItems" in schema:  # a tuple
        shaped = st.tuples(*[body(s, depth + 1) for s in schema["prefixItems"]]).map(list)
    elif schema.get("type") == "array":
        items = body(schema.get("items", {}), depth + 1)
        low = schema.get("minItems", 0)
        shaped = st.lists(items, min_size=low, max_size=max(low, schema.get("maxItems", low + 8)))
    elif schema.get("type") == "null":
        shaped = st.none()
    elif schema.get("type") in ("integer", "number", "boolean", "string"):
        shaped = strategy(schema, past_bounds=False).map(lambda text: _scalar(schema["type"], text))
    else:
        shaped = json_values
    return shaped


def bodies(schema: dict[str, Any]) -> st.SearchStrategy[Any]:
    """Request bodies: of the declared shape, the same with a few nodes mutated, or garbage."""
    shaped = body(schema)
    return st.one_of(shaped, shaped.flatmap(mutated), json_values)


def _scalar(kind: str, text: str | None) -> Any:
    """A query-string value of ``strategy`` as the JSON scalar it spells, where it spells one."""
    try:
        return {"integer": int, "number": float, "boolean": lambda t: {"true": True, "false": False}[t]}.get(
            kind, str)(text)
    except (KeyError, ValueError, TypeError):
        return text


# Values the test site knows, so valid requests find something rather than only 404s.
KNOWN = {
    "zone": ["gate", "shop"], "track_id": ["1", "2", "3"], "track": ["1", "3"], "camera_id": ["north", "south"],
    "tz": ["UTC", "Europe/Paris", "Asia/Kolkata"], "date": ["2023-11-14", "2023-11-15"],
    "types": ["distance_violation", "over_capacity,camera_down", "distance_violation,,over_capacity"],
    "since": ["2023-11-14T22:13:00Z", "1700000000"], "until": ["2023-11-14T22:30:00+01:00", "1700000300.5"],
}


@st.composite
def requests(draw: st.DrawFn, path: str, method: str) -> tuple[str, dict[str, str], Any]:
    """A URL for the operation and its query parameters: half the requests keep every parameter
    to its schema, the other half break one of them (out of range, garbage)."""
    parameters = SPEC["paths"][path][method].get("parameters", [])
    broken = draw(st.sampled_from([None, *range(len(parameters))]))
    url, query = path, {}
    for i, parameter in enumerate(parameters):
        name = parameter["name"]
        values = st.one_of(strategy(parameter["schema"]), st.sampled_from(KNOWN.get(name, ["1"])))
        if i == broken:
            values = st.one_of(strategy(parameter["schema"]), garbage)
        if parameter["in"] == "path":
            url = url.replace("{" + name + "}", quote(draw(values) or "x", safe=""))
        elif i == broken or draw(st.booleans()):
            query[name] = draw(values)
    content = SPEC["paths"][path][method].get("requestBody", {}).get("content", {})
    payload = draw(bodies(content["application/json"]["schema"])) if "application/json" in content else None
    return url, query, payload


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    """A gateway over a SQLite history holding ten minutes of occupancy, tracks, open and ended
    alerts, written by the recorder as in production."""
    site: Site = parse_site(SITE_YAML)
    db = HistoryDatabase.open(str(tmp_path_factory.mktemp("history") / "history.db"))
    clock = FakeClock(T0 + 600 * S)
    recorder = Recorder(db, clock=clock)
    state = GatewayState(site, DatabaseHistory(db, clock=clock), clock=clock, camera_timeout_s=5.0)
    messages: list[Any] = [occupancy(T0 + k * S, total=k % 7, gate=k % 4, shop=k % 11) for k in range(0, 600, 5)]
    messages += [tracks(T0 + k * S, {1: (1.0 + k / 600, 1.0), 2: (2.0, 1.5), 3: (8.0, 2.0)}, violations=[(1, 2)],
                        zones={1: ["gate"], 2: ["gate"], 3: ["shop"]}) for k in range(0, 600, 2)]
    messages += [violation("v1", T0 + 10 * S, end_ns=T0 + 20 * S), violation("v2", T0 + 300 * S),
                 over_capacity("c1", T0 + 100 * S, end_ns=T0 + 200 * S), over_capacity("c2", T0 + 500 * S, zone=None)]
    for message in messages:
        state.apply(message)
        if isinstance(message, Occupancy):
            recorder.on_occupancy(message)
        elif isinstance(message, Tracks):
            recorder.on_tracks(message)
        else:
            recorder.on_event(message)
    recorder.flush()
    try:
        with TestClient(create_app(site, state), raise_server_exceptions=False) as test_client:
            test_client.app.state.access.store.add_user(USER, "viewer", "not-a-real-hash", T0)
            yield test_client
    finally:
        db.close()


def declared_5xx(path: str, method: str) -> set[int]:
    """Server-side codes the spec documents as answers (``/api/health``'s 503: the site is not ok)."""
    return {int(code) for code in SPEC["paths"][path][method].get("responses", {}) if code.startswith("5")}


def check_response(response: Any, url: str, query: dict[str, str], allowed: set[int] = frozenset()) -> None:
    where = f"{url} {query}"
    assert response.status_code < 500 or response.status_code in allowed, \
        f"{where} -> {response.status_code}: {response.text[:500]}"
    if response.status_code in allowed:
        return
    if response.status_code >= 400:
        body = response.json()
        text = body.get("message") or body.get("detail")
        assert isinstance(text, str) and text.strip() and "Traceback" not in text, f"{where}: {body}"
    elif response.headers.get("content-type", "").startswith("application/json"):
        response.json()


def test_every_operation_in_the_spec_answers_with_valid_input(client: TestClient) -> None:
    # The baseline: with no optional parameters every operation succeeds (or says what is not found).
    for path, method in OPERATIONS:
        if method != "get":
            continue
        url = path.replace("{track_id}", "1").replace("{camera_id}", "north").replace("{name}", USER)
        response = client.get(url)
        assert response.status_code in {200} | declared_5xx(path, method), \
            f"{url}: {response.status_code} {response.text[:300]}"


@pytest.mark.parametrize(("path", "method"), OPERATIONS, ids=[f"{m.upper()} {p}" for p, m in OPERATIONS])
def test_no_request_gets_a_server_error(client: TestClient, path: str, method: str) -> None:
    @settings(max_examples=EXAMPLES_PER_OPERATION, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
    @given(request=requests(path, method))
    def run(request: tuple[str, dict[str, str], Any]) -> None:
        url, query, payload = request
        response = client.request(method.upper(), url, params=query, json=payload)
        check_response(response, f"{method.upper()} {url}", query, declared_5xx(path, method))

    run()


@pytest.mark.parametrize(
    ("url", "message"),
    [
        ("/api/occupancy/history?step_s=0", "step_s"),
        ("/api/tracks?limit=abc", "limit"),
        ("/api/tracks/-1", "track_id"),
        ("/api/tracks/999999", "999999"),
        ("/api/cameras/nowhere", "nowhere"),
        ("/api/history/events?format=xml", "format"),
    ],
)
def test_refusals_name_what_was_wrong(client: TestClient, url: str, message: str) -> None:
    response = client.get(url)
    assert 400 <= response.status_code < 500
    body = response.json()
    assert message in (body.get("message") or body.get("detail"))
