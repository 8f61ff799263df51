from __future__ import annotations

import json

from bevflow_services.gateway.openapi import EXPORT_COMMAND, SPEC_PATH, build_spec, render_spec

REQUIRED_PATHS = [
    "/api/occupancy", "/api/occupancy/history", "/api/intervals", "/api/tracks", "/api/tracks/{track_id}",
    "/api/tracks/{track_id}/contacts", "/api/violations", "/api/cameras", "/api/health", "/api/site",
]


def test_the_committed_openapi_spec_is_current() -> None:
    committed = SPEC_PATH.read_text(encoding="utf-8") if SPEC_PATH.exists() else ""
    assert committed == render_spec(), f"{SPEC_PATH} is out of date; regenerate it with: {EXPORT_COMMAND}"


def test_the_spec_has_every_route_and_the_websocket_messages() -> None:
    spec = build_spec()
    assert all(path in spec["paths"] for path in REQUIRED_PATHS)
    assert set(spec["x-websockets"]) == {"/ws/alerts", "/ws/tracks"}
    alert = spec["components"]["schemas"]["AlertMessage"]
    assert {"type", "zone", "start", "tracks"} <= set(alert["required"]) | set(alert["properties"])
    json.dumps(spec)  # plain JSON all the way down
