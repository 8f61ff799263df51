"""The daily report: one local day of a site, from its history.

Peak occupancy (site-wide and per zone, and when), crowded intervals (the rules of
``/api/intervals``: above the crowded level, dips up to ``min_gap_s`` merged, intervals shorter
than ``min_duration_s`` dropped), distance violations by zone and hour, over-capacity alerts with
their durations, and the occupancy curve per ``step_s`` for the charts. Hours are local hours of
the report's time zone, so a day has 23 or 25 of them when the clocks change.

``report_render`` turns a ``DailyReport`` into HTML and PDF.
"""

from __future__ import annotations

from datetime import date, datetime, time, timedelta, tzinfo

import numpy as np
from pydantic import BaseModel, Field

from bevflow.analytics.intervals import crowded_intervals
from bevflow.schemas import Event, iso_utc
from bevflow.site import Site
from bevflow.units import NS_PER_S

from bevflow_services.gateway.history import EventQuery, HistoryStore, OccupancySample
from bevflow_services.gateway.params import to_ns
from bevflow_services.gateway.occupancy import downsample, site_crowded_level

HOUR_NS = 3600 * NS_PER_S
PAGE = 1000


class ZonePeak(BaseModel):
    zone: str | None = Field(description="zone id; null for the whole site")
    name: str
    peak: int
    peak_time: str | None = Field(description="first time the peak was reached, ISO-8601 UTC; null without data")
    peak_ns: int | None
    capacity: int | None
    crowded_level: int | None


class CrowdedSpan(BaseModel):
    zone: str | None
    level: int
    start: str
    end: str
    start_ns: int
    end_ns: int
    duration_s: float
    peak: int
    peak_time: str


class HourlyViolations(BaseModel):
    zone: str | None = Field(description="zone id; null for violations outside every zone")
    name: str
    counts: list[int] = Field(description="violations that started in each local hour of the day")
    total: int


class CapacityAlert(BaseModel):
    id: str
    zone: str | None
    start: str
    end: str | None
    start_ns: int
    end_ns: int | None
    duration_s: float | None = Field(description="null while ongoing")
    peak: int
    capacity: int


class OccupancyCurve(BaseModel):
    step_s: int
    time_ns: list[int]
    total: list[int]
    zones: dict[str, list[int]]


class DailyReport(BaseModel):
    site: str
    date: str = Field(description="the local day, YYYY-MM-DD")
    timezone: str
    start: str = Field(description="local midnight, ISO-8601 UTC")
    end: str = Field(description="the next local midnight, ISO-8601 UTC")
    start_ns: int
    end_ns: int
    samples: int = Field(description="occupancy samples stored for the day: one a second, or one a minute once downsampled")
    peaks: list[ZonePeak] = Field(description="the site first, then each zone")
    crowded: list[CrowdedSpan]
    hours: list[str] = Field(description="local start time of each hour of the day, HH:MM")
    violations: list[HourlyViolations]
    violation_count: int
    violation_mean_s: float | None = Field(description="mean duration of the violations that ended")
    incidents: list[HourlyViolations] = Field(default_factory=list, description="distance incidents (people too close, "
                                              "grouped) that opened in each hour, by zone")
    incident_count: int = 0
    capacity_alerts: list[CapacityAlert]
    occupancy: OccupancyCurve


def day_bounds(day: date, zone: tzinfo) -> tuple[int, int]:
    """[start, end) of a local day in Unix nanoseconds."""
    start = datetime.combine(day, time(0), tzinfo=zone)
    end = datetime.combine(day + timedelta(days=1), time(0), tzinfo=zone)
    return to_ns(start), to_ns(end)


def all_events(history: HistoryStore, since_ns: int, until_ns: int) -> list[Event]:
    """Every alert overlapping [since_ns, until_ns], oldest first."""
    found: list[Event] = []
    while True:
        page, total = history.events(EventQuery(since_ns=since_ns, until_ns=until_ns), PAGE, len(found))
        found.extend(page)
        if not page or len(found) >= total:
            return sorted(found, key=lambda e: (e.start_ns, e.id))


def _peak(zone: str | None, name: str, times: np.ndarray, counts: np.ndarray, capacity: int | None,
          level: int | None) -> ZonePeak:
    if len(counts) == 0:
        return ZonePeak(zone=zone, name=name, peak=0, peak_time=None, peak_ns=None, capacity=capacity, crowded_level=level)
    at = int(np.argmax(counts))  # the first time the peak was reached
    return ZonePeak(zone=zone, name=name, peak=int(counts[at]), peak_time=iso_utc(int(times[at])), peak_ns=int(times[at]),
                    capacity=capacity, crowded_level=level)


def _crowded(zone: str | None, times: np.ndarray, counts: np.ndarray, level: int | None,
             min_gap_s: float, min_duration_s: float) -> list[CrowdedSpan]:
    if level is None or len(times) == 0:
        return []
    spans = []
    for interval in crowded_intervals(times, counts, level, int(min_gap_s * NS_PER_S), int(min_duration_s * NS_PER_S), zone):
        end_ns = interval.end_ns if interval.end_ns is not None else int(times[-1])
        spans.append(CrowdedSpan(zone=zone, level=level, start=iso_utc(interval.start_ns), end=iso_utc(end_ns),
                                 start_ns=interval.start_ns, end_ns=end_ns, duration_s=(end_ns - interval.start_ns) / NS_PER_S,
                                 peak=interval.peak, peak_time=iso_utc(interval.peak_ns)))
    return spans


def _hourly(site: Site, events: list[Event], start_ns: int, hours: int,
            kind: str = "distance_violation") -> list[HourlyViolations]:
    names = {z.id: z.name or z.id for z in site.zones}
    counts: dict[str | None, np.ndarray] = {z.id: np.zeros(hours, dtype=np.int64) for z in site.zones}
    for event in events:
        if event.type == kind and start_ns <= event.start_ns < start_ns + hours * HOUR_NS:
            row = counts.setdefault(event.zone, np.zeros(hours, dtype=np.int64))
            row[(event.start_ns - start_ns) // HOUR_NS] += 1
    return [HourlyViolations(zone=z, name=names.get(z, "outside every zone") if z else "outside every zone",
                             counts=c.tolist(), total=int(c.sum())) for z, c in counts.items()]


def build_daily_report(site: Site, history: HistoryStore, day: date, zone_info: tzinfo, timezone_name: str, *,
                       step_s: int = 60, min_gap_s: float = 30.0, min_duration_s: float = 60.0) -> DailyReport:
    """The report of ``day`` (local to ``zone_info``) for ``site``, from ``history``."""
    start_ns, end_ns = day_bounds(day, zone_info)
    samples: list[OccupancySample] = history.occupancy(start_ns, end_ns - 1)
    times = np.array([s.time_ns for s in samples], dtype=np.int64)
    totals = np.array([s.total for s in samples], dtype=np.int64)
    zone_counts = {z.id: np.array([s.zones.get(z.id, 0) for s in samples], dtype=np.int64) for z in site.zones}

    site_level = site_crowded_level(site)
    peaks = [_peak(None, "whole site", times, totals, site.thresholds.site_capacity, site_level)]
    crowded = _crowded(None, times, totals, site_level, min_gap_s, min_duration_s)
    for z in site.zones:
        peaks.append(_peak(z.id, z.name or z.id, times, zone_counts[z.id], z.capacity, z.effective_crowded_level))
        crowded += _crowded(z.id, times, zone_counts[z.id], z.effective_crowded_level, min_gap_s, min_duration_s)
    crowded.sort(key=lambda c: (c.start_ns, c.zone or ""))

    events = all_events(history, start_ns, end_ns - 1)
    hours = (end_ns - start_ns) // HOUR_NS
    labels = [datetime.fromtimestamp((start_ns + h * HOUR_NS) / NS_PER_S, zone_info).strftime("%H:%M") for h in range(hours)]
    violations = [e for e in events if e.type == "distance_violation" and start_ns <= e.start_ns < end_ns]
    ended = [(e.end_ns - e.start_ns) / NS_PER_S for e in violations if e.end_ns is not None]
    capacity = [CapacityAlert(id=e.id, zone=e.zone, start=iso_utc(e.start_ns),
                              end=None if e.end_ns is None else iso_utc(e.end_ns), start_ns=e.start_ns, end_ns=e.end_ns,
                              duration_s=None if e.end_ns is None else (e.end_ns - e.start_ns) / NS_PER_S,
                              peak=e.peak, capacity=e.capacity)
                for e in events if e.type == "over_capacity"]
    curve = downsample(samples, [z.id for z in site.zones], step_s)
    return DailyReport(
        site=site.site, date=day.isoformat(), timezone=timezone_name, start=iso_utc(start_ns), end=iso_utc(end_ns),
        start_ns=start_ns, end_ns=end_ns, samples=len(samples),
        peaks=peaks, crowded=crowded, hours=labels, violations=_hourly(site, events, start_ns, hours),
        violation_count=len(violations), violation_mean_s=float(np.mean(ended)) if ended else None,
        incidents=_hourly(site, events, start_ns, hours, "distance_incident"),
        incident_count=sum(1 for e in events if e.type == "distance_incident" and start_ns <= e.start_ns < end_ns),
        capacity_alerts=capacity,
        occupancy=OccupancyCurve(step_s=step_s, time_ns=curve.time_ns, total=curve.total, zones=curve.zones),
    )
