"""A ``DailyReport`` as a self-contained HTML page and as a PDF, with the same two charts.

The charts are reportlab drawings: occupancy over the day (the site and each zone) and distance
violations per hour stacked by zone. The PDF embeds them as vector graphics, the HTML page as
inline SVG, so neither needs an image library or files beside it.
"""

from __future__ import annotations

import base64
import hashlib
import html
import io
import re
from datetime import datetime, tzinfo

from reportlab.graphics import renderSVG
from reportlab.graphics.charts.barcharts import VerticalBarChart
from reportlab.graphics.charts.legends import Legend
from reportlab.graphics.charts.lineplots import LinePlot
from reportlab.graphics.shapes import Drawing, String
from reportlab.lib import colors
from reportlab.lib.pagesizes import A4, landscape
from reportlab.lib.styles import getSampleStyleSheet
from reportlab.lib.units import mm
from reportlab.platypus import Paragraph, SimpleDocTemplate, Spacer, Table, TableStyle

from bevflow_services.gateway.daily_report import HOUR_NS, DailyReport
from bevflow.units import NS_PER_S

PALETTE = [colors.HexColor(c) for c in ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b",
                                        "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")]
WIDTH, HEIGHT = 720, 220


def local(time_ns: int | None, zone: tzinfo, with_date: bool = False) -> str:
    if time_ns is None:
        return "-"
    moment = datetime.fromtimestamp(time_ns / NS_PER_S, zone)
    return moment.strftime("%Y-%m-%d %H:%M:%S" if with_date else "%H:%M:%S")


def duration(seconds: float | None) -> str:
    if seconds is None:
        return "ongoing"
    minutes, secs = divmod(int(round(seconds)), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours} h {minutes:02d} min" if hours else f"{minutes} min {secs:02d} s" if minutes else f"{secs} s"


def _empty(drawing: Drawing, text: str) -> Drawing:
    drawing.add(String(WIDTH / 2, HEIGHT / 2, text, textAnchor="middle", fontSize=11, fillColor=colors.grey))
    return drawing


def _legend(drawing: Drawing, pairs: list[tuple[colors.Color, str]]) -> None:
    legend = Legend()
    legend.x, legend.y = WIDTH - 150, HEIGHT - 10
    legend.alignment = "right"
    legend.fontSize = 8
    legend.colorNamePairs = pairs
    drawing.add(legend)


def occupancy_chart(report: DailyReport) -> Drawing:
    """People in the site and in each zone over the day (highest count per step)."""
    drawing = Drawing(WIDTH, HEIGHT)
    curve = report.occupancy
    if not curve.time_ns:
        return _empty(drawing, "no occupancy recorded this day")
    hours = [(t - report.start_ns) / HOUR_NS for t in curve.time_ns]
    series = [("whole site", curve.total), *((z, counts) for z, counts in curve.zones.items())]
    plot = LinePlot()
    plot.x, plot.y, plot.width, plot.height = 40, 30, WIDTH - 210, HEIGHT - 45
    plot.data = [list(zip(hours, counts, strict=True)) for _, counts in series]
    for i, _ in enumerate(series):
        plot.lines[i].strokeColor = colors.black if i == 0 else PALETTE[(i - 1) % len(PALETTE)]
        plot.lines[i].strokeWidth = 1.2 if i == 0 else 0.8
    day_hours = len(report.hours)
    plot.xValueAxis.valueMin, plot.xValueAxis.valueMax, plot.xValueAxis.valueStep = 0, day_hours, 3
    plot.xValueAxis.labelTextFormat = lambda h: report.hours[int(h)] if int(h) < day_hours else ""
    plot.yValueAxis.valueMin = 0
    plot.yValueAxis.valueMax = max(1, max(max(c) for _, c in series if c)) * 1.1
    drawing.add(plot)
    _legend(drawing, [(plot.lines[i].strokeColor, name) for i, (name, _) in enumerate(series)])
    return drawing


def violations_chart(report: DailyReport) -> Drawing:
    """Distance violations that started in each hour, stacked by zone."""
    drawing = Drawing(WIDTH, HEIGHT)
    rows = [v for v in report.violations if v.total]
    if not rows:
        return _empty(drawing, "no distance violations this day")
    chart = VerticalBarChart()
    chart.x, chart.y, chart.width, chart.height = 40, 30, WIDTH - 210, HEIGHT - 45
    chart.data = [row.counts for row in rows]
    chart.categoryAxis.style = "stacked"
    chart.categoryAxis.categoryNames = [h[:2] for h in report.hours]
    chart.categoryAxis.labels.fontSize = 7
    chart.valueAxis.valueMin = 0
    for i in range(len(rows)):
        chart.bars[i].fillColor = PALETTE[i % len(PALETTE)]
        chart.bars[i].strokeColor = None
    drawing.add(chart)
    _legend(drawing, [(PALETTE[i % len(PALETTE)], row.name) for i, row in enumerate(rows)])
    return drawing


def _svg(drawing: Drawing) -> str:
    text = renderSVG.drawToString(drawing)
    return _presentation_attributes(text[text.index("<svg"):])  # no XML prolog or doctype: it sits inside HTML


STYLE_ATTRIBUTE = re.compile(r'\sstyle="([^"]*)"')


def _presentation_attributes(svg: str) -> str:
    """``style="fill: red; stroke: none"`` as ``fill="red" stroke="none"``: a Content-Security-Policy
    without 'unsafe-inline' blocks style attributes (the charts came out black), never SVG's own
    presentation attributes, which take the same names and values."""

    def attributes(match: re.Match[str]) -> str:
        pairs = (d.split(":", 1) for d in match.group(1).split(";") if ":" in d)
        return "".join(f' {name.strip()}="{html.escape(value.strip())}"' for name, value in pairs)

    return STYLE_ATTRIBUTE.sub(attributes, svg)


# --- the tables, shared by both formats ----------------------------------------------------------
def tables(report: DailyReport, zone: tzinfo) -> dict[str, tuple[list[str], list[list[str]]]]:
    """Each table as (header, rows) of text."""
    names = {p.zone: p.name for p in report.peaks}
    return {
        "Peak occupancy": (["zone", "peak", "at", "capacity", "crowded above"], [
            [p.name, str(p.peak), local(p.peak_ns, zone), "-" if p.capacity is None else str(p.capacity),
             "-" if p.crowded_level is None else str(p.crowded_level)] for p in report.peaks]),
        "Crowded intervals": (["zone", "from", "to", "lasted", "peak"], [
            [names.get(c.zone, c.zone or "whole site"), local(c.start_ns, zone), local(c.end_ns, zone),
             duration(c.duration_s), str(c.peak)] for c in report.crowded]),
        "Distance incidents by hour": (["zone", *[h[:2] for h in report.hours], "total"], [
            [v.name, *[str(c) if c else "" for c in v.counts], str(v.total)] for v in report.incidents]),
        "Distance violations by hour": (["zone", *[h[:2] for h in report.hours], "total"], [
            [v.name, *[str(c) if c else "" for c in v.counts], str(v.total)] for v in report.violations]),
        "Over-capacity alerts": (["zone", "from", "to", "lasted", "peak", "capacity"], [
            [names.get(a.zone, a.zone or "whole site"), local(a.start_ns, zone, True), local(a.end_ns, zone, True),
             duration(a.duration_s), str(a.peak),
             str(a.capacity)] for a in report.capacity_alerts]),
    }


def _summary(report: DailyReport) -> str:
    mean = "" if report.violation_mean_s is None else f", lasting {duration(report.violation_mean_s)} on average"
    return (f"{report.incident_count} distance incidents (groups too close); "
            f"{report.violation_count} distance violations between pairs{mean}; {len(report.capacity_alerts)} over-capacity alerts; "
            f"{len(report.crowded)} crowded intervals; {report.samples} occupancy samples.")


# --- HTML ----------------------------------------------------------------------------------------
STYLE = """body{font-family:system-ui,sans-serif;margin:2em;color:#222}table{border-collapse:collapse;margin:.5em 0 1.5em}
td,th{border:1px solid #ccc;padding:2px 6px;font-size:13px;text-align:right}td:first-child,th:first-child{text-align:left}
th{background:#f2f2f2}h1{margin-bottom:0}.muted{color:#777}"""


# The gateway's pages allow no inline style but this one, by its hash (``routes/reports``), so that a
# saved report stays one self-contained file.
STYLE_HASH = "sha256-" + base64.b64encode(hashlib.sha256(STYLE.encode()).digest()).decode()


def render_html(report: DailyReport, zone: tzinfo) -> str:
    parts = [f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(report.site)} "
             f"{report.date}</title><link rel='icon' href='/favicon.svg'><style>{STYLE}</style></head><body>",
             f"<h1>Daily report: {html.escape(report.site)}, {report.date}</h1>",
             f"<p class='muted'>{html.escape(report.timezone)}, local midnight to midnight "
             f"({report.start} to {report.end})</p><p>{html.escape(_summary(report))}</p>",
             "<h2>Occupancy</h2>", _svg(occupancy_chart(report)),
             "<h2>Distance violations per hour</h2>", _svg(violations_chart(report))]
    for title, (header, rows) in tables(report, zone).items():
        parts.append(f"<h2>{html.escape(title)}</h2>")
        if not rows:
            parts.append("<p class='muted'>none</p>")
            continue
        head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
        body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>" for row in rows)
        parts.append(f"<table><tr>{head}</tr>{body}</table>")
    parts.append("</body></html>")
    return "\n".join(parts)


# --- PDF -----------------------------------------------------------------------------------------
def render_pdf(report: DailyReport, zone: tzinfo) -> bytes:
    styles = getSampleStyleSheet()
    out = io.BytesIO()
    doc = SimpleDocTemplate(out, pagesize=landscape(A4), leftMargin=12 * mm, rightMargin=12 * mm,
                            topMargin=12 * mm, bottomMargin=12 * mm,
                            title=f"Daily report {report.site} {report.date}", author="bevflow")
    story = [Paragraph(f"Daily report: {html.escape(report.site)}, {report.date}", styles["Title"]),
             Paragraph(f"{html.escape(report.timezone)}, local midnight to midnight ({report.start} to {report.end})",
                       styles["Normal"]),
             Paragraph(html.escape(_summary(report)), styles["Normal"]),
             Paragraph("Occupancy", styles["Heading2"]), occupancy_chart(report),
             Paragraph("Distance violations per hour", styles["Heading2"]), violations_chart(report)]
    for title, (header, rows) in tables(report, zone).items():
        story.append(Paragraph(html.escape(title), styles["Heading2"]))
        if not rows:
            story.append(Paragraph("none", styles["Normal"]))
            continue
        table = Table([header, *rows], repeatRows=1)
        table.setStyle(TableStyle([
            ("FONTSIZE", (0, 0), (-1, -1), 7 if len(header) > 10 else 9),
            ("GRID", (0, 0), (-1, -1), 0.25, colors.lightgrey),
            ("BACKGROUND", (0, 0), (-1, 0), colors.HexColor("#f2f2f2")),
            ("ALIGN", (1, 0), (-1, -1), "RIGHT"),
        ]))
        story += [table, Spacer(1, 4 * mm)]
    doc.build(story)
    return out.getvalue()
