"""Contact tracing (paper 3.8, "tracking of individuals who violate the measures"): who came close
to a given track, when, for how long and how close.

It works on a ``TrackHistory``, whose samples of all tracks share timestamps; two tracks are
compared at every timestamp where both have a sample, all at once with numpy. A sample counts as
contact when the two feet positions are closer than ``limit_m`` (strictly, as for violations).
Duration is sample-and-hold over the traced track's samples: a contact sample counts until the
traced track's next sample, and the last stored sample counts for nothing.

>>> from bevflow.analytics.trajectories import TrackHistory
>>> history = TrackHistory(sample_period_s=1.0)
>>> for s in range(3):
...     _ = history.update(s * 1_000_000_000, [1, 2], [[0.0, 0.0], [3.0 - s, 0.0]])
>>> [(c.track, c.min_distance_m, c.duration_s) for c in contacts(history, 1, limit_m=2.0)]
[(2, 1.0, 0.0)]
"""

from __future__ import annotations

import numpy as np

from bevflow.analytics.trajectories import TrackHistory
from bevflow.schemas import Contact
from bevflow.units import NS_PER_S


def contacts(
    history: TrackHistory,
    track_id: int,
    limit_m: float,
    start_ns: int | None = None,
    end_ns: int | None = None,
) -> list[Contact]:
    """Every other track that came closer than ``limit_m`` to ``track_id`` within the optional
    [start_ns, end_ns] window, ordered by first contact. KeyError if ``track_id`` has no history."""
    if limit_m <= 0:
        raise ValueError(f"limit_m must be > 0, got {limit_m}")
    traced = history.trajectory(track_id)
    times, xy = traced.times_ns, traced.xy
    hold_ns = np.diff(times, append=times[-1:]) if len(times) else times

    others, other_t, other_xy = history.samples()
    at = np.searchsorted(times, other_t).clip(max=max(len(times) - 1, 0))
    aligned = (others != track_id) & (len(times) > 0)
    if len(times):
        aligned &= times[at] == other_t
    if start_ns is not None:
        aligned &= other_t >= start_ns
    if end_ns is not None:
        aligned &= other_t <= end_ns
    rows = np.flatnonzero(aligned)
    dist = np.hypot(*(other_xy[rows] - xy[at[rows]]).T)
    near = dist < limit_m
    rows, dist = rows[near], dist[near]
    if len(rows) == 0:
        return []

    # Group contact samples by other track, each group ordered by time.
    order = np.lexsort((other_t[rows], others[rows]))
    rows, dist = rows[order], dist[order]
    ids, first = np.unique(others[rows], return_index=True)
    last = np.concatenate([first[1:], [len(rows)]]) - 1
    duration_ns = np.add.reduceat(hold_ns[at[rows]], first)
    # The closest sample of each group: the first one reaching the group's minimum.
    closest = np.array([a + int(np.argmin(dist[a : b + 1])) for a, b in zip(first, last, strict=True)])

    found = [
        Contact(
            track=int(ids[g]),
            first_ns=int(other_t[rows[first[g]]]),
            last_ns=int(other_t[rows[last[g]]]),
            duration_s=float(duration_ns[g]) / NS_PER_S,
            min_distance_m=float(dist[closest[g]]),
            closest_ns=int(other_t[rows[closest[g]]]),
            limit_m=float(limit_m),
        )
        for g in range(len(ids))
    ]
    return sorted(found, key=lambda c: (c.first_ns, c.track))
