"""Contacts a person can act on: the fragments of one contact joined, the fleeting ones left out.

A tracker that loses someone and finds them again gives them a new id, so one long contact reads
as several short ones with different people (one person collected 24 contacts in 108 s in the
demo, most 0-1 s long). ``merge_fragments`` joins a contact with a later one when the second
person's track began within ``gap_s`` after the first one's ended, within ``join_m`` of where it
ended: probably the same person. ``actionable`` then drops contacts shorter than a minimum (the
site's ``violation_min_duration_s``: a pass in a corridor is not a contact to trace).

>>> from bevflow.schemas import Contact
>>> def contact(track, first_s, last_s):
...     return Contact(track=track, first_ns=first_s * 10**9, last_ns=last_s * 10**9, duration_s=last_s - first_s,
...                    min_distance_m=1.0, closest_ns=first_s * 10**9, limit_m=2.0)
>>> spans = {7: TrackSpan(0, 10 * 10**9, (0.0, 0.0), (5.0, 0.0)), 9: TrackSpan(11 * 10**9, 30 * 10**9, (5.5, 0.0), (9.0, 0.0))}
>>> [(c.track, c.tracks, c.duration_s) for c in merge_fragments([contact(7, 2, 10), contact(9, 11, 20)], spans)]
[(7, [7, 9], 17.0)]
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from bevflow.schemas import Contact
from bevflow.units import NS_PER_S


@dataclass(frozen=True)
class TrackSpan:
    """When and where a track was first and last seen."""

    first_ns: int
    last_ns: int
    first_xy: tuple[float, float]
    last_xy: tuple[float, float]


def _continues(before: TrackSpan, after: TrackSpan, gap_ns: int, join_m: float) -> bool:
    """Whether ``after`` is probably the same person as ``before``, found again."""
    gap = after.first_ns - before.last_ns
    moved = math.hypot(after.first_xy[0] - before.last_xy[0], after.first_xy[1] - before.last_xy[1])
    return 0 <= gap <= gap_ns and moved <= join_m


def _joined(a: Contact, b: Contact) -> Contact:
    closest = a if a.min_distance_m <= b.min_distance_m else b
    return Contact(track=a.track, first_ns=a.first_ns, last_ns=b.last_ns, duration_s=a.duration_s + b.duration_s,
                   min_distance_m=closest.min_distance_m, closest_ns=closest.closest_ns, limit_m=a.limit_m,
                   tracks=(a.tracks or [a.track]) + (b.tracks or [b.track]))


def merge_fragments(found: list[Contact], spans: dict[int, TrackSpan], gap_s: float = 3.0,
                    join_m: float = 1.5) -> list[Contact]:
    """``found`` (one traced track's contacts) with the fragments of one person joined, ordered by
    first contact; ``spans`` holds the other tracks' spans (a contact whose track has none is kept
    as it is)."""
    gap_ns = round(gap_s * NS_PER_S)
    chains: list[Contact] = []
    for c in sorted(found, key=lambda c: (c.first_ns, c.track)):
        span = spans.get(c.track)
        follows = None if span is None else next(
            (k for k, chain in enumerate(chains)
             if (last := spans.get((chain.tracks or [chain.track])[-1])) is not None and _continues(last, span, gap_ns, join_m)),
            None)
        if follows is None:
            chains.append(c)
        else:
            chains[follows] = _joined(chains[follows], c)
    return chains


def actionable(found: list[Contact], min_duration_s: float) -> list[Contact]:
    """The contacts that lasted at least ``min_duration_s``."""
    return [c for c in found if c.duration_s >= min_duration_s]
