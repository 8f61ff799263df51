"""``/api/reports/daily`` over the in-memory history and the history database (both backends)."""

from __future__ import annotations

import base64
import hashlib
import re
import sys
import zlib
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from bevflow.site import Site

import bevflow_services.gateway
from tests.services.gateway.feed import S, FakeClock, incident, occupancy, over_capacity, violation
from tests.services.gateway.routes.test_history import History, gateway_over

H, MIN = 3600 * S, 60 * S
DAY = 1700006400 * S  # 2023-11-15T00:00:00Z


@pytest.fixture(params=["memory", "sqlite", "postgresql"])
def day(request: pytest.FixtureRequest, site: Site, clock: FakeClock, tmp_path: Path) -> Iterator[History]:
    """2023-11-15 (UTC) of the test site, with a sample just before and just after it."""
    with gateway_over(request.param, site, clock, tmp_path) as history:
        messages = [occupancy(DAY - 10 * S, 20, gate=3)]  # the day before: not in the report
        for t in range(DAY + H, DAY + 3 * H, 10 * S):
            crowded_site = DAY + 2 * H <= t < DAY + 2 * H + 10 * MIN
            gate = 4 if t == DAY + H + 31 * MIN else 3 if DAY + H + 30 * MIN <= t < DAY + H + 32 * MIN else 1
            messages.append(occupancy(t, 11 if crowded_site else 5, gate=gate))
        messages.append(occupancy(DAY + 24 * H, 30))  # the next day
        messages += [violation("a", DAY + H + 15 * MIN, zone="gate", end_ns=DAY + H + 15 * MIN + 5 * S),
                     violation("b", DAY + H + 45 * MIN, zone="gate", end_ns=DAY + H + 45 * MIN + 8 * S),
                     violation("c", DAY + 13 * H + 20 * MIN, zone="shop"),
                     violation("d", DAY + 13 * H + 5 * MIN, zone=None, end_ns=DAY + 13 * H + 5 * MIN + 3 * S),
                     violation("e", DAY - S, zone="gate", end_ns=DAY + 5 * S),  # started the day before
                     over_capacity("cap", DAY + 2 * H, zone=None, end_ns=DAY + 2 * H + 10 * MIN),
                     incident("inc", DAY + H + 15 * MIN, zone="gate", end_ns=DAY + H + 16 * MIN)]
        history.feed(*messages)  # one commit, as the recorder would make
        yield history


def test_peaks_are_the_highest_counts_of_the_day_and_when(day: History) -> None:
    report = day.client.get("/api/reports/daily?date=2023-11-15").json()
    assert (report["start_ns"], report["end_ns"], report["timezone"]) == (DAY, DAY + 24 * H, "UTC")
    peaks = {p["zone"]: (p["peak"], p["peak_ns"]) for p in report["peaks"]}
    assert peaks == {None: (11, DAY + 2 * H), "gate": (4, DAY + H + 31 * MIN), "shop": (0, DAY + H)}


def test_crowded_intervals_follow_the_zone_levels(day: History) -> None:
    crowded = day.client.get("/api/reports/daily?date=2023-11-15").json()["crowded"]
    assert [(c["zone"], c["level"], c["start_ns"], c["end_ns"], c["duration_s"], c["peak"]) for c in crowded] == [
        ("gate", 2, DAY + H + 30 * MIN, DAY + H + 32 * MIN, 120.0, 4),
        (None, 9, DAY + 2 * H, DAY + 2 * H + 10 * MIN, 600.0, 11),
    ]


def test_violations_by_zone_and_hour(day: History) -> None:
    report = day.client.get("/api/reports/daily?date=2023-11-15").json()
    hourly = {v["zone"]: v["counts"] for v in report["violations"]}
    assert set(hourly) == {"gate", "shop", None} and all(len(c) == 24 for c in hourly.values())
    assert {z: {h: n for h, n in enumerate(c) if n} for z, c in hourly.items()} == {
        "gate": {1: 2}, "shop": {13: 1}, None: {13: 1}}
    assert report["violation_count"] == 4
    assert report["violation_mean_s"] == pytest.approx((5 + 8 + 3) / 3)
    assert [(a["id"], a["duration_s"], a["peak"]) for a in report["capacity_alerts"]] == [("cap", 600.0, 5)]


def test_the_day_is_local_to_the_time_zone(day: History) -> None:
    report = day.client.get("/api/reports/daily?date=2023-11-15&tz=Europe/Paris").json()  # UTC+1 in November
    assert report["start_ns"] == DAY - H and report["hours"][:2] == ["00:00", "01:00"]
    hourly = {v["zone"]: {h: n for h, n in enumerate(v["counts"]) if n} for v in report["violations"]}
    assert hourly == {"gate": {0: 1, 2: 2}, "shop": {14: 1}, None: {14: 1}}  # "e" now starts in the day
    assert {p["zone"]: p["peak"] for p in report["peaks"]}[None] == 20  # 23:59:50 UTC is 00:59:50 in Paris


@pytest.mark.parametrize(
    ("date", "hours", "missing_or_twice"),
    [("2024-03-31", 23, "02:00"), ("2024-10-27", 25, "02:00"), ("2024-06-01", 24, None)],
)
def test_days_when_the_clocks_change_have_23_or_25_hours(client: TestClient, date, hours, missing_or_twice) -> None:
    labels = client.get(f"/api/reports/daily?date={date}&tz=Europe/Paris").json()["hours"]
    assert len(labels) == hours and len(labels[0]) == 5
    if hours == 23:
        assert missing_or_twice not in labels
    elif hours == 25:
        assert labels.count(missing_or_twice) == 2


def test_the_default_day_is_today(client: TestClient) -> None:
    assert client.get("/api/reports/daily").json()["date"] == "2023-11-14"  # the test clock's day


def test_the_html_report_has_both_charts_and_every_table(day: History) -> None:
    response = day.client.get("/api/reports/daily?date=2023-11-15&format=html")
    assert response.headers["content-type"].startswith("text/html")
    page = response.text
    assert page.count("<svg") == 2 and "Daily report: hall, 2023-11-15" in page
    for title in ("Peak occupancy", "Crowded intervals", "Distance violations by hour", "Over-capacity alerts"):
        assert f"<h2>{title}</h2>" in page
    assert "<td>Gate</td><td>4</td><td>01:31:00</td>" in page
    assert "1 distance incidents (groups too close); 4 distance violations between pairs, lasting 5 s on average" in page
    assert "<h2>Distance incidents by hour</h2>" in page


def test_the_html_report_is_styled_under_the_gateways_policy(day: History) -> None:
    """No style attribute (the charts use SVG presentation attributes) and one stylesheet, allowed by its hash."""
    response = day.client.get("/api/reports/daily?date=2023-11-15&format=html")
    policy, page = response.headers["content-security-policy"], response.text
    assert " style=" not in page and page.count("<style>") == 1
    style = page.split("<style>")[1].split("</style>")[0]
    digest = base64.b64encode(hashlib.sha256(style.encode()).digest()).decode()
    assert f"style-src 'self' 'sha256-{digest}';" in policy and "script-src 'self';" in policy
    assert 'fill="rgb(' in page  # the charts keep their colours


def pdf_text(pdf: bytes) -> bytes:
    """The page contents of a reportlab PDF (ASCII85 and Flate encoded streams), decoded."""
    streams = re.findall(rb"stream\r?\n(.*?)endstream", pdf, re.S)
    return b"".join(zlib.decompress(base64.a85decode(s.strip().removesuffix(b"~>"))) for s in streams)


def test_the_pdf_report_holds_the_same_content(day: History) -> None:
    response = day.client.get("/api/reports/daily?date=2023-11-15&format=pdf")
    assert response.headers["content-type"] == "application/pdf"
    assert 'filename="report-hall-2023-11-15.pdf"' in response.headers["content-disposition"]
    assert response.content.startswith(b"%PDF-")
    text = pdf_text(response.content)
    for expected in (b"(Daily report: hall, 2023-11-15)", b"(Peak occupancy)", b"(Gate)", b"(01:31:00)",
                     b"(whole site)", b"(10 min 00 s)"):
        assert expected in text, expected


def test_an_empty_day_still_renders(client: TestClient) -> None:
    assert client.get("/api/reports/daily?date=2020-01-01&format=pdf").status_code == 200
    page = client.get("/api/reports/daily?date=2020-01-01&format=html").text
    assert "no occupancy recorded this day" in page and "no distance violations this day" in page


@pytest.mark.parametrize(
    ("query", "status", "message"),
    [
        ("tz=Mars/Olympus", 400, "tz: unknown time zone 'Mars/Olympus'"),
        ("tz=../../etc/passwd", 400, "tz: unknown time zone"),
        ("date=2023-13-01", 422, "date"),
        ("date=1900-01-01", 400, "date: 1900-01-01 is outside"),
        ("format=docx", 422, "format"),
    ],
)
def test_bad_report_requests_name_the_parameter(client: TestClient, query, status, message) -> None:
    response = client.get(f"/api/reports/daily?{query}")
    assert response.status_code == status and message in response.text


@pytest.mark.parametrize("fmt", ["html", "pdf"])
def test_without_reportlab_html_and_pdf_answer_501_naming_the_extra(client: TestClient, monkeypatch: pytest.MonkeyPatch,
                                                                     fmt: str) -> None:
    # As on a gateway installed without the 'reports' extra: reportlab, and so the renderer, cannot be imported.
    for name in ["reportlab", *(n for n in sys.modules if n.startswith("reportlab."))]:
        monkeypatch.setitem(sys.modules, name, None)
    monkeypatch.delitem(sys.modules, "bevflow_services.gateway.report_render", raising=False)
    monkeypatch.delattr(bevflow_services.gateway, "report_render", raising=False)
    response = client.get(f"/api/reports/daily?date=2020-01-01&format={fmt}")
    assert response.status_code == 501 and "pip install 'bevflow[reports]'" in response.json()["detail"]
    assert client.get("/api/reports/daily?date=2020-01-01").status_code == 200  # JSON needs nothing more
