from __future__ import annotations

from datetime import UTC, datetime, timedelta, timezone

import pytest
from fastapi import HTTPException

from bevflow_services.gateway.params import TimeRange, recent, split_csv, time_range, to_ns


@pytest.mark.parametrize(
    ("moment", "ns"),
    [
        (datetime(1970, 1, 1, tzinfo=UTC), 0),
        (datetime(1970, 1, 1), 0),  # naive is UTC
        (datetime(2023, 11, 14, 22, 13, 20, 250_000, tzinfo=UTC), 1_700_000_000_250_000_000),
        (datetime(2023, 11, 15, 0, 13, 20, tzinfo=timezone(timedelta(hours=2))), 1_700_000_000_000_000_000),
    ],
)
def test_to_ns(moment: datetime, ns: int) -> None:
    assert to_ns(moment) == ns


def test_time_range_refuses_since_after_until() -> None:
    early, late = datetime(2024, 1, 1, tzinfo=UTC), datetime(2024, 1, 2, tzinfo=UTC)
    assert time_range(early, late) == TimeRange(to_ns(early), to_ns(late))
    with pytest.raises(HTTPException) as refused:
        time_range(late, early)
    assert refused.value.status_code == 400 and "since" in refused.value.detail


@pytest.mark.parametrize(
    ("window", "last_s", "newest", "expected"),
    [
        (TimeRange(None, None), None, 100, TimeRange(None, None)),
        (TimeRange(None, 90), 2.0, 10_000_000_000, TimeRange(8_000_000_000, 90)),
        (TimeRange(None, None), 2.0, None, TimeRange(None, None)),  # no data yet: nothing to be recent to
    ],
)
def test_recent(window: TimeRange, last_s, newest, expected: TimeRange) -> None:
    assert recent(window, last_s, newest) == expected


def test_recent_refuses_since_with_last_s() -> None:
    with pytest.raises(HTTPException, match="since or last_s"):
        recent(TimeRange(5, None), 2.0, 100)


@pytest.mark.parametrize(
    ("value", "expected"),
    [(None, None), ("", None), (" a, b ,,a", frozenset({"a", "b"}))],
)
def test_split_csv(value, expected) -> None:
    assert split_csv(value, "types", ("a", "b")) == expected


def test_split_csv_names_the_parameter_and_the_allowed_values() -> None:
    with pytest.raises(HTTPException) as refused:
        split_csv("a,zz", "types", ("a", "b"))
    assert refused.value.detail == "types: unknown value(s) zz; allowed: a, b"
