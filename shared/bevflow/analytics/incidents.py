"""Distance incidents: the pair violations of ``DistanceMonitor`` grouped into what a supervisor acts on.

A pair alert per two people floods a control room: five people standing together are ten pairs,
and a tracker that loses and finds someone again restarts every pair. Here, at each tick, the open
violation pairs are joined into connected groups (people linked through anyone in between), and
each group is followed over time as one **candidate**:

- a group continues a candidate when it shares a person with the candidate's latest group, or,
  sharing no one (ids change when the tracker loses someone), when its centre lies within the
  social distance of the candidate's latest centre; a group touching several candidates merges
  them into the oldest;
- a candidate **opens** an incident once it has lasted ``min_duration_s`` from its first violation
  (short contacts never become incidents) and is still active at that tick;
- it stays one incident while the group persists, whoever joins or leaves, and **closes** after
  ``quiet_s`` with no violation in it; ``end_ns`` is the last tick with one;
- while open it is published again (same id) when its current people change, at most once every
  ``update_every_s``.

Severity comes from the number of people and the duration (``severity``). An incident that ended
before ``ack_min_s`` and stayed low severity carries ``needs_acknowledgement`` false: it is over
and was minor, so nobody needs to confirm having seen it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from bevflow.analytics.companions import Companions
from bevflow.analytics.positions import FloatArray, IntArray, seconds_to_ns
from bevflow.analytics.zones import ZoneIndex
from bevflow.schemas import DistanceIncident
from bevflow.site import Thresholds, Zone
from bevflow.units import NS_PER_S

# (people at once, seconds) from which an incident is of that severity; the first that applies wins.
Severity = Literal["low", "medium", "high"]
SEVERITY_RULES: tuple[tuple[Severity, int, float], ...] = (("high", 5, 300.0), ("medium", 3, 60.0))
MAX_LISTED_TRACKS = 50  # ``tracks`` of a long incident with much id churn stays readable


def severity(people: int, duration_s: float) -> Severity:
    """"high", "medium" or "low" for a group of ``people`` (at most at once) lasting ``duration_s``.

    >>> severity(2, 10.0), severity(3, 10.0), severity(2, 90.0), severity(6, 10.0)
    ('low', 'medium', 'medium', 'high')
    """
    for name, people_from, seconds_from in SEVERITY_RULES:
        if people >= people_from or duration_s >= seconds_from:
            return name
    return "low"


def connected_groups(pairs: IntArray) -> list[list[int]]:
    """The track ids linked by (K, 2) ``pairs``, one sorted list per connected group, in order of
    their smallest id.

    >>> connected_groups(np.array([[1, 2], [2, 3], [7, 9]]))
    [[1, 2, 3], [7, 9]]
    """
    parent: dict[int, int] = {}

    def root(a: int) -> int:
        while parent.setdefault(a, a) != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for a, b in np.asarray(pairs, dtype=np.int64).reshape(-1, 2).tolist():
        ra, rb = root(a), root(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    groups: dict[int, list[int]] = {}
    for a in sorted(parent):
        groups.setdefault(root(a), []).append(a)
    return list(groups.values())


@dataclass
class _Group:
    """One tick's connected group: its people, centre and closest pair distance."""

    members: frozenset[int]
    centre: tuple[float, float]
    min_d: float


@dataclass
class _Candidate:
    key: int  # first tick, then a counter: unique and ordered by age
    start_ns: int
    last_active_ns: int
    members: frozenset[int]
    centre: tuple[float, float]
    min_d: float
    involved: list[int] = field(default_factory=list)
    people: int = 0
    open: bool = False
    published: frozenset[int] | None = None  # the current people last published
    published_ns: int = 0

    def absorb(self, group: _Group, t: int) -> None:
        self.last_active_ns = t
        self.members, self.centre = group.members, group.centre
        self.min_d = min(self.min_d, group.min_d)
        self.people = max(self.people, len(group.members))
        self.involved += sorted(group.members.difference(self.involved))

    def merge(self, other: _Candidate) -> None:
        self.start_ns = min(self.start_ns, other.start_ns)
        self.min_d = min(self.min_d, other.min_d)
        self.people = max(self.people, other.people)
        self.involved += [i for i in other.involved if i not in self.involved]


class IncidentTracker:
    """Turns each tick's open violation pairs into ``DistanceIncident`` open, update and close
    events (rules above).

    >>> from bevflow.site import Thresholds
    >>> th = Thresholds(incident_min_duration_s=1.0, incident_quiet_s=1.0, incident_companion_window_s=0.0)
    >>> tracker = IncidentTracker(th)
    >>> xy = [[0, 0], [1, 0], [1.5, 0.5]]
    >>> [[e.end_ns is None for e in tracker.update(t * NS_PER_S, [[1, 2], [2, 3]], [1, 2, 3], xy)] for t in range(3)]
    [[], [True], []]
    >>> [e.people for e in tracker.update(5 * NS_PER_S, [], [1, 2, 3], xy)]
    [3]
    """

    def __init__(self, thresholds: Thresholds, zones: tuple[Zone, ...] | list[Zone] = (), update_every_s: float = 2.0) -> None:
        self.limit_m = float(thresholds.social_distance_m)
        self.min_duration_ns = seconds_to_ns(thresholds.incident_min_duration_s)
        self.quiet_ns = seconds_to_ns(thresholds.incident_quiet_s)
        self.ack_min_ns = seconds_to_ns(thresholds.incident_ack_min_s)
        self.update_every_ns = seconds_to_ns(update_every_s)
        self._zones = ZoneIndex(zones)
        self.companions = Companions(thresholds.incident_companion_window_s)
        self._candidates: list[_Candidate] = []
        self._merged: list[_Candidate] = []  # open incidents merged into an older one at this tick
        self._next_key = 0

    @property
    def open_incidents(self) -> list[DistanceIncident]:
        """The incidents open now, as their latest messages (oldest first)."""
        return [self._event(c, None, c.last_active_ns) for c in self._candidates if c.open]

    def update(self, time_ns: int, pairs: ArrayLike, ids: ArrayLike, xy: ArrayLike) -> list[DistanceIncident]:
        """Advance to ``time_ns`` with the (K, 2) track-id pairs in violation now and the tick's
        track ids and (N, 2) feet positions; returns the incidents that opened, changed or closed
        (closes first). A tick with no pairs lets every incident run towards its close."""
        t = int(time_ns)
        self.companions.update(t, ids, pairs)
        strangers = self.companions.strangers(pairs)
        groups = self._groups(strangers, np.asarray(ids), np.asarray(xy, float))
        self._follow(groups, t)
        ended = [c for c in self._candidates if t - c.last_active_ns > self.quiet_ns]
        self._candidates = [c for c in self._candidates if c not in ended]
        events = [self._event(c, t, t) for c in self._merged]  # their people carry on in the older one
        events += [self._event(c, c.last_active_ns, t) for c in ended if c.open]
        self._merged = []
        for c in self._candidates:
            if c.last_active_ns != t:
                continue
            if not c.open and t - c.start_ns >= self.min_duration_ns:
                c.open = True
            if c.open and c.members != c.published and (c.published is None or t - c.published_ns >= self.update_every_ns):
                c.published, c.published_ns = c.members, t
                events.append(self._event(c, None, t))
        return events

    def _groups(self, pairs: IntArray, ids: IntArray, xy: FloatArray) -> list[_Group]:
        row = {int(i): r for r, i in enumerate(ids.tolist())}
        known = [p for p in pairs.tolist() if p[0] in row and p[1] in row]
        if not known:
            return []
        components = connected_groups(np.array(known, dtype=np.int64))
        group_of = {m: g for g, members in enumerate(components) for m in members}
        # Each group's closest pair, for all pairs at once: a crowd's tick has thousands of them.
        a, b = (np.array([row[p[k]] for p in known]) for k in (0, 1))
        closest = np.full(len(components), np.inf)
        np.minimum.at(closest, [group_of[p[0]] for p in known], np.hypot(*(xy[a] - xy[b]).T))
        people = [row[m] for members in components for m in members]
        which = np.repeat(np.arange(len(components)), [len(members) for members in components])
        summed = np.stack([np.bincount(which, weights=xy[people, k]) for k in (0, 1)], axis=1)
        centre = summed / np.bincount(which)[:, None]
        return [_Group(frozenset(members), (cx, cy), d)
                for members, (cx, cy), d in zip(components, centre.tolist(), closest.tolist(), strict=True)]

    def _follow(self, groups: list[_Group], t: int) -> None:
        """Give each group its candidate (continued, merged or new), largest groups first."""
        claimed: set[int] = set()
        by_member: dict[int, list[_Candidate]] = {}  # the candidates each person is in, oldest first
        for c in self._candidates:
            for m in c.members:
                by_member.setdefault(m, []).append(c)
        for group in sorted(groups, key=lambda g: -len(g.members)):
            found = {c.key: c for m in group.members for c in by_member.get(m, ()) if c.key not in claimed}
            touching = [found[k] for k in sorted(found)]
            if not touching:
                touching = [c for c in self._candidates if c.key not in claimed and c.last_active_ns != t
                            and math.hypot(c.centre[0] - group.centre[0], c.centre[1] - group.centre[1]) <= self.limit_m][:1]
            if touching:
                keep = min(touching, key=lambda c: (not c.open, c.start_ns, c.key))
                for other in touching:
                    if other is not keep:
                        keep.merge(other)
                        self._candidates.remove(other)
                        claimed.add(other.key)  # gone: no later group may find it
                        if other.open:
                            self._merged.append(other)
            else:
                keep = _Candidate(self._next_key, t, t, group.members, group.centre, group.min_d)
                self._next_key += 1
                self._candidates.append(keep)
            keep.absorb(group, t)
            claimed.add(keep.key)

    def _event(self, c: _Candidate, end_ns: int | None, raised_ns: int) -> DistanceIncident:
        last = c.last_active_ns
        duration_ns = (end_ns if end_ns is not None else last) - c.start_ns
        level = severity(c.people, duration_ns / NS_PER_S)
        short = end_ns is not None and duration_ns < self.ack_min_ns and level == "low"
        zone = self._zones.first_zone(np.array([c.centre])) if len(self._zones) else [None]
        return DistanceIncident(
            id=f"incident-{c.start_ns}-{c.key}",
            start_ns=c.start_ns,
            end_ns=end_ns,
            zone=zone[0],
            tracks=c.involved[:MAX_LISTED_TRACKS],
            people=max(2, c.people),
            current=sorted(c.members) if end_ns is None else [],
            min_distance_m=c.min_d,
            limit_m=self.limit_m,
            position=c.centre,
            last_active_ns=last,
            severity=level,
            needs_acknowledgement=not short,
            raised_ns=raised_ns,
        )
