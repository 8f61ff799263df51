"""Wire messages: round trips with the columnar types, event decoding, and what is refused."""

from __future__ import annotations

import inspect
import json
import math
import typing
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from pydantic import BaseModel, ValidationError

import bevflow.schemas as schemas
from bevflow.detections import Boxes, Cylinders
from bevflow.schemas import (
    EVENT_TYPES,
    CalibrationDrift,
    CameraCylinders,
    CameraHealthEvent,
    CylinderEstimate,
    Detections2D,
    DistanceIncident,
    DistanceViolation,
    FrameHeader,
    Occupancy,
    OverCapacity,
    Tracks,
    TrackState,
    ZoneOccupancy,
    decode_event,
)

NAN = float("nan")


# --- boxes --------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "boxes",
    [
        pytest.param(
            Boxes(xyxy=[[10.25, 20.5, 50.125, 90.0], [0.0, 0.0, 1e-3, 7.0]], confidence=[0.9, 0.123456789]), id="two"
        ),
        pytest.param(Boxes(xyxy=[[1.0, 2.0, 3.0, 4.0]]), id="default-confidence"),
        pytest.param(Boxes.empty(), id="empty"),
    ],
)
def test_boxes_round_trip_through_json(boxes: Boxes) -> None:
    message = Detections2D.from_boxes("cam-a", seq=7, capture_ns=1_700_000_000_123_456_789, boxes=boxes)
    decoded = Detections2D.model_validate_json(message.model_dump_json())
    assert decoded == message and decoded.capture_ns == 1_700_000_000_123_456_789
    back = decoded.to_boxes()
    np.testing.assert_array_equal(back.xyxy, boxes.xyxy.reshape(-1, 4))
    np.testing.assert_array_equal(back.confidence, boxes.confidence)


def test_detections_without_confidence_mean_certain() -> None:
    boxes = Detections2D(camera="a", seq=0, capture_ns=0, boxes=[(0, 0, 1, 1), (2, 2, 3, 3)]).to_boxes()
    np.testing.assert_array_equal(boxes.confidence, [1.0, 1.0])


def test_detections_refuse_confidences_that_do_not_match_boxes() -> None:
    with pytest.raises(ValidationError):
        Detections2D(camera="a", seq=0, capture_ns=0, boxes=[(0, 0, 1, 1), (2, 2, 3, 3)], confidence=[0.5])


# --- cylinders ----------------------------------------------------------------------------------
def test_cylinders_round_trip_drops_rows_without_a_position() -> None:
    cyl = Cylinders(
        xy=[[1.0, 2.0], [NAN, 0.0], [3.5, -4.25], [0.0, np.inf], [5.0, 6.0]],
        height=[1.6, 1.7, 1.8, 1.7, 1.55],
        radius=[0.25, 0.3, 0.35, 0.3, 0.4],
        camera=[3] * 5,
        score=[0.5, 0.0, 1.2, 0.0, -0.1],  # fits may score slightly outside [0, 1]
        occluded=[False, False, True, False, True],
    )
    message = CameraCylinders.from_cylinders("cam-b", seq=1, capture_ns=99, cyl=cyl)
    assert len(message.cylinders) == 3
    back = CameraCylinders.model_validate_json(message.model_dump_json()).to_cylinders(camera_index=6)
    kept = [0, 2, 4]
    np.testing.assert_array_equal(back.xy, cyl.xy[kept])
    np.testing.assert_array_equal(back.height, cyl.height[kept])
    np.testing.assert_array_equal(back.radius, cyl.radius[kept])
    np.testing.assert_array_equal(back.occluded, cyl.occluded[kept])
    np.testing.assert_array_equal(back.score, [0.5, 1.0, 0.0])  # clipped into [0, 1]
    np.testing.assert_array_equal(back.camera, [6, 6, 6])  # the receiver's index, not the sender's


@pytest.mark.parametrize("xy", [np.zeros((0, 2)), [[NAN, NAN]]], ids=["empty", "all-dropped"])
def test_cylinders_round_trip_of_nothing(xy) -> None:
    message = CameraCylinders.from_cylinders("cam-b", seq=1, capture_ns=99, cyl=Cylinders(xy=xy))
    assert message.cylinders == []
    back = message.to_cylinders(camera_index=0)
    assert len(back) == 0 and back.xy.shape == (0, 2)


def test_cylinders_with_non_finite_size_are_dropped_too() -> None:
    cyl = Cylinders(xy=[[1.0, 2.0], [3.0, 4.0]], height=[NAN, 1.7])
    assert len(CameraCylinders.from_cylinders("cam-b", seq=1, capture_ns=99, cyl=cyl).cylinders) == 1


def test_cylinder_covariances_cross_the_wire_exactly() -> None:
    cov = np.array([[[0.04, 0.013], [0.013, 0.09]], [[0.1, -0.0301], [-0.0301, 0.02]]])
    cyl = Cylinders(xy=[[1.0, 2.0], [3.0, 4.0]], covariance=cov)
    message = CameraCylinders.from_cylinders("cam-b", seq=1, capture_ns=99, cyl=cyl)
    assert [c.covariance for c in message.cylinders] == [(0.04, 0.013, 0.09), (0.1, -0.0301, 0.02)]
    back = CameraCylinders.model_validate_json(message.model_dump_json()).to_cylinders(camera_index=0)
    np.testing.assert_array_equal(back.covariance, cov)


def test_cylinders_without_covariance_serialise_as_before() -> None:
    message = CameraCylinders.from_cylinders("cam-b", seq=1, capture_ns=99, cyl=Cylinders(xy=[[1.0, 2.0]]))
    assert "covariance" not in json.loads(message.model_dump_json())["cylinders"][0]
    assert message.to_cylinders(camera_index=0).covariance is None


def test_unusable_covariances_are_left_for_the_receiver() -> None:
    cov = np.array([[[0.04, 0.0], [0.0, 0.09]], [[NAN, 0.0], [0.0, 0.09]], [[0.01, 0.2], [0.2, 0.01]]])
    cyl = Cylinders(xy=[[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]], covariance=cov)
    message = CameraCylinders.from_cylinders("cam-b", seq=1, capture_ns=99, cyl=cyl)
    assert [c.covariance for c in message.cylinders] == [(0.04, 0.0, 0.09), None, None]
    back = message.to_cylinders(camera_index=0).covariance
    np.testing.assert_array_equal(back[0], cov[0])
    assert np.isnan(back[1:]).all()  # fusion computes these rows


@pytest.mark.parametrize(
    "covariance", [(0.0, 0.0, 1.0), (1.0, 0.0, -1.0), (1.0, 2.0, 1.0), (1.0, NAN, 1.0)],
    ids=["zero-variance", "negative", "not-positive-definite", "nan"],
)
def test_a_covariance_that_is_not_positive_definite_is_refused(covariance) -> None:
    with pytest.raises(ValidationError):
        CylinderEstimate(xy=(0.0, 0.0), height=1.7, radius=0.3, covariance=covariance)


def test_measured_statures_cross_the_wire_and_unmeasured_ones_stay_absent() -> None:
    cyl = Cylinders(xy=[[1.0, 2.0], [3.0, 4.0]], stature=[1.73, NAN])
    message = CameraCylinders.from_cylinders("cam-b", seq=1, capture_ns=99, cyl=cyl)
    wire = json.loads(message.model_dump_json())["cylinders"]
    assert wire[0]["stature"] == 1.73 and "stature" not in wire[1]
    back = CameraCylinders.model_validate_json(message.model_dump_json()).to_cylinders(camera_index=0)
    np.testing.assert_array_equal(back.stature, [1.73, NAN])


@pytest.mark.parametrize("stature", [0.0, -1.7, NAN, math.inf])
def test_a_stature_that_is_not_a_height_is_refused(stature: float) -> None:
    with pytest.raises(ValidationError):
        CylinderEstimate(xy=(0.0, 0.0), height=1.7, radius=0.3, stature=stature)


# --- events -------------------------------------------------------------------------------------
EVENTS = [
    pytest.param(
        DistanceViolation(id="dv-1", start_ns=10, tracks=[3, 4], min_distance_m=1.2, limit_m=2.0, position=(1.0, 2.0)),
        id="distance",
    ),
    pytest.param(
        DistanceIncident(id="di-1", start_ns=10, tracks=[3, 4, 5], people=3, current=[3, 4], min_distance_m=0.9,
                         limit_m=2.0, position=(1.0, 2.0), last_active_ns=15, severity="medium"),
        id="incident",
    ),
    pytest.param(OverCapacity(id="oc-1", start_ns=10, end_ns=20, zone="bar", capacity=10, peak=13), id="over-capacity"),
    pytest.param(
        CalibrationDrift(id="cd-1", start_ns=10, camera="cam-a", shift_m=0.3, reference_camera="cam-b"), id="drift"
    ),
    pytest.param(
        CameraHealthEvent(id="ch-1", start_ns=10, type="camera_down", camera="cam-a", reason="no frames for 5 s"),
        id="camera-down",
    ),
    pytest.param(CameraHealthEvent(id="ch-2", start_ns=10, type="camera_up", camera="cam-a"), id="camera-up"),
]


@pytest.mark.parametrize("event", EVENTS)
def test_events_decode_to_their_own_class(event: BaseModel) -> None:
    for payload in (event.model_dump_json(), event.model_dump_json().encode()):
        decoded = decode_event(payload)
        assert type(decoded) is type(event) and decoded == event


def test_event_types_list_every_event() -> None:
    decoded_types = {json.loads(e.values[0].model_dump_json())["type"] for e in EVENTS}
    assert set(EVENT_TYPES) == decoded_types
    assert len(EVENT_TYPES) == len(set(EVENT_TYPES))


@pytest.mark.parametrize(
    ("payload", "error"),
    [
        pytest.param({"type": "fire_alarm", "id": "x", "start_ns": 0}, "union_tag_invalid", id="unknown-type"),
        pytest.param({"id": "x", "start_ns": 0, "capacity": 1, "peak": 2}, "union_tag_not_found", id="no-type"),
        pytest.param({"type": "over_capacity", "id": "x", "start_ns": 0, "capacity": 1}, "missing", id="missing-field"),
        pytest.param(
            {"type": "over_capacity", "id": "x", "start_ns": 0, "capacity": 1, "peak": 2, "colour": "red"},
            "extra_forbidden",
            id="extra-field",
        ),
        pytest.param(
            {"type": "over_capacity", "id": "x", "start_ns": 0, "capacity": 1, "peak": 2, "schema_version": 2},
            "literal_error",
            id="newer-schema",
        ),
        pytest.param(
            {"type": "over_capacity", "id": "x", "start_ns": -1, "capacity": 1, "peak": 2},
            "greater_than_equal",
            id="negative-time",
        ),
    ],
)
def test_bad_events_are_refused(payload: dict[str, Any], error: str) -> None:
    with pytest.raises(ValidationError) as caught:
        decode_event(json.dumps(payload))
    assert error in {e["type"] for e in caught.value.errors()}


# --- what every message refuses -----------------------------------------------------------------
def _schema_models() -> list[type[BaseModel]]:
    return [
        m
        for _, m in inspect.getmembers(schemas, inspect.isclass)
        if issubclass(m, BaseModel) and m.__module__ == schemas.__name__
    ]


@pytest.mark.parametrize("model", _schema_models(), ids=lambda m: m.__name__)
def test_every_message_is_frozen_and_forbids_extra_fields(model: type[BaseModel]) -> None:
    assert model.model_config.get("extra") == "forbid"
    assert model.model_config.get("frozen") is True


VALID: list[tuple[type[BaseModel], dict[str, Any]]] = [
    (FrameHeader, {"camera": "a", "seq": 0, "capture_ns": 5, "width": 640, "height": 480}),
    (Detections2D, {"camera": "a", "seq": 0, "capture_ns": 5, "boxes": [[0, 0, 1, 1]], "confidence": [0.5]}),
    (
        CameraCylinders,
        {"camera": "a", "seq": 0, "capture_ns": 5, "cylinders": [{"xy": [1, 2], "height": 1.7, "radius": 0.3}]},
    ),
    (Tracks, {"site": "s", "time_ns": 5, "tracks": [{"id": 1, "xy": [1, 2], "velocity": [0.1, 0]}]}),
    (Occupancy, {"site": "s", "time_ns": 5, "total": 3, "zones": [{"id": "z", "count": 2}]}),
]


@pytest.mark.parametrize(("model", "fields"), VALID, ids=lambda v: getattr(v, "__name__", ""))
def test_messages_round_trip_and_refuse_unknown_fields(model: type[BaseModel], fields: dict[str, Any]) -> None:
    message = model.model_validate(fields)
    assert model.model_validate_json(message.model_dump_json()) == message
    with pytest.raises(ValidationError, match="Extra inputs are not permitted"):
        model.model_validate({**fields, "unexpected": 1})
    with pytest.raises(ValidationError):
        model.model_validate({**fields, "schema_version": 2})
    first = next(iter(fields))
    with pytest.raises(ValidationError, match="frozen"):
        setattr(message, first, fields[first])


@pytest.mark.parametrize(
    ("model", "fields"),
    [
        pytest.param(Detections2D, {"camera": "a", "seq": 0, "capture_ns": 0, "boxes": [[NAN, 0, 1, 1]]}, id="box"),
        pytest.param(CylinderEstimate, {"xy": [1.0, NAN], "height": 1.7, "radius": 0.3}, id="cylinder-xy"),
        pytest.param(CylinderEstimate, {"xy": [1.0, 2.0], "height": float("inf"), "radius": 0.3}, id="cylinder-height"),
        pytest.param(
            CylinderEstimate, {"xy": [1.0, 2.0], "height": 1.7, "radius": 0.3, "score": NAN}, id="cylinder-score"
        ),
        pytest.param(TrackState, {"id": 1, "xy": [NAN, 0.0]}, id="track-xy"),
        pytest.param(TrackState, {"id": 1, "xy": [0.0, 0.0], "velocity": [0.0, float("-inf")]}, id="track-velocity"),
        pytest.param(
            DistanceViolation,
            {"id": "d", "start_ns": 0, "min_distance_m": NAN, "limit_m": 2.0},
            id="violation-distance",
        ),
        pytest.param(
            DistanceViolation,
            {"id": "d", "start_ns": 0, "min_distance_m": 1.0, "limit_m": 2.0, "position": [NAN, 1.0]},
            id="violation-position",
        ),
        pytest.param(CalibrationDrift, {"id": "c", "start_ns": 0, "camera": "a", "shift_m": NAN}, id="drift"),
    ],
)
def test_nan_and_infinity_are_refused(model: type[BaseModel], fields: dict[str, Any]) -> None:
    with pytest.raises(ValidationError):
        model.model_validate(fields)


def test_nan_in_json_text_is_refused() -> None:
    # Python's json module writes NaN as a bare token; it must not get through as a position.
    text = json.dumps(
        {"camera": "a", "seq": 0, "capture_ns": 0, "cylinders": [{"xy": [NAN, 1.0], "height": 1.7, "radius": 0.3}]}
    )
    assert "NaN" in text
    with pytest.raises(ValidationError):
        CameraCylinders.model_validate_json(text)


@pytest.mark.parametrize(
    ("model", "fields"),
    [
        pytest.param(
            FrameHeader, {"camera": "a", "seq": -1, "capture_ns": 0, "width": 1, "height": 1}, id="negative-seq"
        ),
        pytest.param(FrameHeader, {"camera": "a", "seq": 0, "capture_ns": 0, "width": 0, "height": 1}, id="zero-width"),
        pytest.param(
            FrameHeader,
            {"camera": "a", "seq": 0, "capture_ns": 0, "width": 1, "height": 1, "encoding": "png"},
            id="unknown-encoding",
        ),
        pytest.param(
            Detections2D, {"camera": "a", "seq": 0, "capture_ns": 0, "boxes": [[0, 0, 1]]}, id="box-with-3-numbers"
        ),
        pytest.param(
            Detections2D,
            {"camera": "a", "seq": 0, "capture_ns": 0, "boxes": [[0, 0, 1, 1]], "confidence": [1.5]},
            id="confidence-above-1",
        ),
        pytest.param(CylinderEstimate, {"xy": [0, 0], "height": 0.0, "radius": 0.3}, id="zero-height"),
        pytest.param(ZoneOccupancy, {"id": "z", "count": -1}, id="negative-count"),
    ],
)
def test_out_of_range_values_are_refused(model: type[BaseModel], fields: dict[str, Any]) -> None:
    with pytest.raises(ValidationError):
        model.model_validate(fields)


def test_event_union_matches_event_types() -> None:
    # The discriminated union and EVENT_TYPES are written separately; keep them in step.
    union = typing.get_args(typing.get_args(schemas.Event)[0])
    literals = {value for cls in union for value in typing.get_args(cls.model_fields["type"].annotation)}
    assert literals == set(EVENT_TYPES)


def _columns(n: int, **changes: Any) -> SimpleNamespace:
    rng = np.random.default_rng(n)
    columns = {"id": np.arange(1, n + 1), "xy": rng.uniform(0, 40, (n, 2)), "velocity": rng.normal(0, 1, (n, 2)),
               "height": rng.uniform(1.5, 1.9, n), "radius": rng.uniform(0.2, 0.4, n)}  # fmt: skip
    return SimpleNamespace(**{**columns, **changes})


@pytest.mark.parametrize(
    ("n", "cameras", "zones", "violations"),
    [
        (0, [], [], []),
        (1, [["cam1"]], [[]], []),
        (3, [["cam1", "cam2"], [], ["cam2"]], [["gate"], ["gate", "hall"], []], [(1, 3)]),
    ],
)
def test_tracks_wire_json_is_the_message_built_from_the_same_columns(n, cameras, zones, violations) -> None:
    columns = _columns(n)
    states = [
        TrackState(id=int(columns.id[k]), xy=tuple(columns.xy[k]), velocity=tuple(columns.velocity[k]),
                   height=float(columns.height[k]), radius=float(columns.radius[k]), cameras=cameras[k], zones=zones[k])
        for k in range(n)
    ]  # fmt: skip
    got = Tracks.model_validate_json(Tracks.wire_json("hall", 7, columns, cameras, zones, violations))
    exact = {"id", "cameras", "zones"}
    assert got.model_dump(exclude={"tracks": {"__all__": set(TrackState.model_fields) - exact}}) == Tracks(
        site="hall", time_ns=7, tracks=states, violations=violations
    ).model_dump(exclude={"tracks": {"__all__": set(TrackState.model_fields) - exact}})
    for field in ("xy", "velocity", "height", "radius"):  # to 0.1 mm
        np.testing.assert_allclose([getattr(t, field) for t in got.tracks], [getattr(t, field) for t in states], atol=5e-5)


@pytest.mark.parametrize(
    ("changes", "time_ns", "rows"),
    [
        ({"xy": np.array([[np.nan, 1.0]])}, 0, 1),
        ({"velocity": np.array([[np.inf, 0.0]])}, 0, 1),
        ({"height": np.array([0.0])}, 0, 1),
        ({"radius": np.array([-0.3])}, 0, 1),
        ({}, -1, 1),
        ({}, 0, 2),  # two camera and zone lists for one track
    ],
)
def test_tracks_wire_json_refuses_columns_the_message_would_refuse(changes, time_ns, rows) -> None:
    with pytest.raises(ValueError, match="track"):
        Tracks.wire_json("hall", time_ns, _columns(1, **changes), [[]] * rows, [[]] * rows, [])
