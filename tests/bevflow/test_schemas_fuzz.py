"""Property-based fuzzing of every wire-message decoder: whatever bytes arrive, decoding gives a
valid message or a ``ValidationError`` (never another exception), and what is accepted
re-encodes to itself and converts to the columnar types."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel, TypeAdapter, ValidationError

from bevflow import schemas

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# One valid example of every message that crosses a process boundary, as plain JSON.
VALID_MESSAGES: dict[str, tuple[Any, dict[str, Any]]] = {
    "FrameHeader": (schemas.FrameHeader, {"camera": "a", "seq": 3, "capture_ns": 5, "width": 640, "height": 480}),
    "Detections2D": (schemas.Detections2D, {"camera": "a", "seq": 0, "capture_ns": 5,
                                            "boxes": [[0, 0, 10, 20], [5, 5, 8, 9]], "confidence": [0.5, 1.0]}),
    "CameraCylinders": (schemas.CameraCylinders, {"camera": "a", "seq": 0, "capture_ns": 5, "cylinders": [
        {"xy": [1, 2], "height": 1.7, "radius": 0.3, "score": 0.9, "occluded": True}]}),
    "SimulatedTruth": (schemas.SimulatedTruth, {"site": "s", "frame": 2, "capture_ns": 5, "tracks": [1, 2],
                                                "positions": [[0, 0], [1.5, 2.5]]}),
    "Tracks": (schemas.Tracks, {"site": "s", "time_ns": 5, "violations": [[1, 2]], "tracks": [
        {"id": 1, "xy": [1, 2], "velocity": [0.1, 0], "cameras": ["a"], "zones": ["z"]},
        {"id": 2, "xy": [2, 2]}]}),
    "Occupancy": (schemas.Occupancy, {"site": "s", "time_ns": 5, "total": 3, "capacity": 10,
                                      "zones": [{"id": "z", "name": "Zed", "count": 2, "capacity": 4}]}),
    "DistanceViolation": (schemas.Event, {"type": "distance_violation", "id": "dv", "start_ns": 1, "tracks": [1, 2],
                                          "min_distance_m": 1.2, "limit_m": 2.0, "position": [1, 1], "zone": "z"}),
    "DistanceIncident": (schemas.Event, {"type": "distance_incident", "id": "di", "start_ns": 1, "tracks": [1, 2, 3],
                                         "people": 3, "current": [1, 3], "min_distance_m": 0.8, "limit_m": 2.0,
                                         "position": [1, 1], "last_active_ns": 4, "severity": "medium",
                                         "needs_acknowledgement": False}),
    "OverCapacity": (schemas.Event, {"type": "over_capacity", "id": "oc", "start_ns": 1, "end_ns": 9,
                                     "capacity": 3, "peak": 5, "raised_ns": 9}),
    "CalibrationDrift": (schemas.Event, {"type": "calibration_drift", "id": "cd", "start_ns": 1, "camera": "a",
                                         "shift_m": 0.3, "reference_camera": "b"}),
    "CameraHealthEvent": (schemas.Event, {"type": "camera_down", "id": "ch", "start_ns": 1, "camera": "a",
                                          "reason": "no frames"}),
    "OpenAlerts": (schemas.OpenAlerts, {"site": "s", "time_ns": 5, "ids": ["dv", "oc"]}),
    "ServiceMetrics": (schemas.ServiceMetrics, {
        "site": "s", "service": "tracker", "instance": "t1", "time_ns": 5,
        "values": [{"name": "camera_frames_late", "labels": {"camera": "c"}, "value": 2}],
        "histograms": [{"name": "tick_duration_seconds", "bounds": [0.01, 0.1], "counts": [1, 3], "count": 4, "sum": 0.2}]}),
}
VALID_MESSAGES["AlertMessage"] = (schemas.AlertMessage, json.loads(schemas.AlertMessage.from_event(
    schemas.decode_event(json.dumps(VALID_MESSAGES["DistanceViolation"][1]))).model_dump_json()))

ADAPTERS = {name: TypeAdapter(model) for name, (model, _) in VALID_MESSAGES.items()}
NAMES = sorted(VALID_MESSAGES)

# JSON values, including the awkward ones: huge and negative integers, floats at the edges,
# unicode, deep nesting.
json_scalars = st.one_of(
    st.none(), st.booleans(),
    st.integers(), st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=20),
    st.sampled_from(["distance_violation", "over_capacity", "camera_down", "bgr8", "jpeg", "", "1"]),
)
json_values = st.recursive(
    json_scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=5), st.dictionaries(st.text(max_size=10), inner, max_size=5)),
    max_leaves=20,
)


@st.composite
def mutated(draw: st.DrawFn, valid: Any) -> Any:
    """``valid`` with one node (or a few) replaced, removed, or given a sibling."""
    value = json.loads(json.dumps(valid))
    for _ in range(draw(st.integers(1, 3))):
        value = _mutate_once(draw, value)
    return value


def _mutate_once(draw: st.DrawFn, value: Any) -> Any:
    if isinstance(value, dict) and value and draw(st.booleans()):
        key = draw(st.sampled_from(sorted(value)))
        action = draw(st.sampled_from(["descend", "descend", "drop", "replace", "add"]))
        if action == "descend":
            value[key] = _mutate_once(draw, value[key])
        elif action == "drop":
            del value[key]
        elif action == "replace":
            value[key] = draw(json_values)
        else:
            value[draw(st.text(max_size=8))] = draw(json_values)
        return value
    if isinstance(value, list) and value and draw(st.booleans()):
        i = draw(st.integers(0, len(value) - 1))
        action = draw(st.sampled_from(["descend", "descend", "drop", "duplicate", "replace"]))
        if action == "descend":
            value[i] = _mutate_once(draw, value[i])
        elif action == "drop":
            del value[i]
        elif action == "duplicate":
            value.append(value[i])
        else:
            value[i] = draw(json_values)
        return value
    return draw(st.one_of(json_values, st.sampled_from([-1, 0, 2**63, -(2**63) - 1, 1e308, -1e-300, "NaN"])))


def decode(name: str, payload: bytes | str) -> Any:
    """The decoder a service uses for ``name``; events go through ``decode_event``."""
    if VALID_MESSAGES[name][0] is schemas.Event:
        return schemas.decode_event(payload)
    return ADAPTERS[name].validate_json(payload)


def check_accepted(name: str, message: Any) -> None:
    """What a decoder accepts is a real message: it re-encodes to itself, its numbers are
    finite, and it converts to the columnar types the pipeline uses."""
    model = VALID_MESSAGES[name][0]
    encoded = ADAPTERS[name].dump_json(message)
    assert ADAPTERS[name].validate_json(encoded) == message
    json.loads(encoded, parse_constant=lambda c: pytest.fail(f"{name} encoded {c}"))
    if isinstance(message, schemas.Detections2D):
        boxes = message.to_boxes()
        assert len(boxes) == len(message.boxes) and np.isfinite(boxes.xyxy).all()
    if isinstance(message, schemas.CameraCylinders):
        cylinders = message.to_cylinders(0)
        assert len(cylinders) == len(message.cylinders) and np.isfinite(cylinders.xy).all()
    if model is schemas.Event:
        assert message.type in schemas.EVENT_TYPES
        schemas.AlertMessage.from_event(message)


def test_the_valid_examples_are_valid() -> None:
    for name, (_, fields) in VALID_MESSAGES.items():
        check_accepted(name, decode(name, json.dumps(fields)))


@FUZZ
@given(name=st.sampled_from(NAMES), payload=st.binary(max_size=200))
def test_arbitrary_bytes_decode_or_raise_validation_error(name: str, payload: bytes) -> None:
    try:
        message = decode(name, payload)
    except ValidationError:
        return
    check_accepted(name, message)


@FUZZ
@given(name=st.sampled_from(NAMES), tree=json_values)
def test_arbitrary_json_decodes_or_raises_validation_error(name: str, tree: Any) -> None:
    try:
        message = decode(name, json.dumps(tree))
    except ValidationError:
        return
    check_accepted(name, message)


@FUZZ
@given(data=st.data(), name=st.sampled_from(NAMES))
def test_mutated_valid_messages_decode_or_raise_validation_error(data: st.DataObject, name: str) -> None:
    tree = data.draw(mutated(VALID_MESSAGES[name][1]))
    try:
        message = decode(name, json.dumps(tree))
    except ValidationError as exc:
        assert str(exc)  # a message a log line can show
        return
    check_accepted(name, message)


@FUZZ
@given(data=st.data(), name=st.sampled_from(NAMES))
def test_nan_and_infinity_in_json_text_are_refused(data: st.DataObject, name: str) -> None:
    # Python's json writes NaN/Infinity, which are not JSON; a peer doing the same must be refused.
    tree = json.loads(json.dumps(VALID_MESSAGES[name][1]))
    numbers = list(_number_paths(tree))
    if not numbers:
        return
    path = data.draw(st.sampled_from(numbers))
    node = tree
    for step in path[:-1]:
        node = node[step]
    node[path[-1]] = data.draw(st.sampled_from([math.nan, math.inf, -math.inf]))
    with pytest.raises(ValidationError):
        decode(name, json.dumps(tree))


def _number_paths(tree: Any, path: tuple[Any, ...] = ()) -> Any:
    """Paths to every number in ``tree`` (the version tag aside)."""
    if isinstance(tree, (int, float)) and not isinstance(tree, bool):
        if path[-1:] != ("schema_version",):
            yield path
        return
    items = tree.items() if isinstance(tree, dict) else enumerate(tree) if isinstance(tree, list) else ()
    for key, value in items:
        yield from _number_paths(value, (*path, key))


@pytest.mark.parametrize("name", NAMES)
def test_a_message_from_a_newer_release_is_refused_by_version(name: str) -> None:
    fields = {**VALID_MESSAGES[name][1], "schema_version": schemas.SCHEMA_VERSION + 1}
    with pytest.raises(ValidationError, match="schema_version"):
        decode(name, json.dumps(fields))


def _all_models() -> list[type[BaseModel]]:
    return [m for m in vars(schemas).values()
            if isinstance(m, type) and issubclass(m, schemas.Message) and m not in (schemas.Message, schemas.EventBase)]


def test_every_message_has_a_fuzzed_example() -> None:
    covered = {type(decode(name, json.dumps(fields))) for name, (_, fields) in VALID_MESSAGES.items()}
    missing = {m.__name__ for m in _all_models()} - {m.__name__ for m in covered}
    assert not missing, f"add an example of {sorted(missing)} to VALID_MESSAGES"
