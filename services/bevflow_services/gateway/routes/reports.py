"""``/api/reports/daily``: one day of the site, as JSON, an HTML page or a PDF.

    /api/reports/daily?date=2024-05-01&tz=Europe/Paris&format=pdf

Peak occupancy, crowded intervals, distance violations by zone and hour, over-capacity alerts
with their durations, and charts of occupancy and violations (``daily_report``,
``report_render``). The day runs from local midnight to local midnight in ``tz``. HTML and PDF
need reportlab (the 'reports' extra): without it they answer 501 saying so, and JSON still works.
"""

from __future__ import annotations

import re
from datetime import UTC, date, datetime, tzinfo
from types import ModuleType
from typing import Annotated, Any, Literal
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import HTMLResponse, Response

from bevflow_services import extras
from bevflow_services.gateway.auth_headers import content_security_policy
from bevflow_services.gateway.daily_report import DailyReport, build_daily_report
from bevflow_services.gateway.params import StateDep
from bevflow.units import NS_PER_S

router = APIRouter(prefix="/api/reports", tags=["reports"])

DateParam = Annotated[date | None, Query(alias="date", description="the local day, YYYY-MM-DD (default: today in tz)")]
TimezoneParam = Annotated[str, Query(max_length=64, description="IANA time zone of the day, e.g. Europe/Paris (default UTC)")]
ReportFormat = Annotated[Literal["json", "html", "pdf"], Query(alias="format", description="json, html or pdf")]
FIRST_DAY, LAST_DAY = date(1970, 1, 2), date(2262, 4, 10)
RESPONSES: dict[int | str, dict[str, Any]] = {200: {
    "content": {"text/html": {"schema": {"type": "string"}},
                "application/pdf": {"schema": {"type": "string", "format": "binary"}}},
    "description": "the report as JSON, or as HTML or PDF with format=html or format=pdf"},
    501: {"description": "format=html or format=pdf on a gateway installed without the 'reports' extra (the detail says "
          "what to install); JSON still works"}}


def time_zone(name: str) -> tzinfo:
    """The named IANA zone; 400 naming the parameter when it is unknown."""
    if name.upper() in ("UTC", "Z"):
        return UTC
    try:
        return ZoneInfo(name)
    except (ZoneInfoNotFoundError, ValueError):
        raise HTTPException(400, f"tz: unknown time zone {name!r}; use an IANA name such as Europe/Paris or UTC") from None


def renderer() -> ModuleType:
    """The HTML and PDF renderer; 501 naming the extra where reportlab is not installed."""
    try:
        from bevflow_services.gateway import report_render
    except ModuleNotFoundError as exc:
        if extras.extra_for(exc) != "reports":
            raise
        raise HTTPException(501, f"HTML and PDF reports: the gateway {extras.install_hint('reports')} "
                                 "(format=json works without it)") from None
    return report_render


@router.get("/daily", response_model=DailyReport, responses=RESPONSES, summary="The daily report (JSON, HTML or PDF)")
def daily_report(state: StateDep, day: DateParam = None, tz: TimezoneParam = "UTC", fmt: ReportFormat = "json") -> Any:
    zone = time_zone(tz)
    if day is None:
        day = datetime.fromtimestamp(state.clock() / NS_PER_S, zone).date()
    if not FIRST_DAY <= day <= LAST_DAY:  # capture times are int64 nanoseconds since 1970
        raise HTTPException(400, f"date: {day.isoformat()} is outside {FIRST_DAY} to {LAST_DAY}")
    report = build_daily_report(state.site, state.history, day, zone, tz)
    if fmt == "html":  # the gateway's policy, plus the report's own stylesheet
        render = renderer()
        policy = content_security_policy("/api/reports/daily", style_hashes=[render.STYLE_HASH])
        return HTMLResponse(render.render_html(report, zone), headers={"Content-Security-Policy": policy})
    if fmt == "pdf":
        name = re.sub(r"[^A-Za-z0-9_.-]", "_", f"report-{state.site.site}-{report.date}")
        return Response(renderer().render_pdf(report, zone), media_type="application/pdf",
                        headers={"Content-Disposition": f'inline; filename="{name}.pdf"'})
    return report
