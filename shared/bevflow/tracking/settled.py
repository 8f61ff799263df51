"""Tracks reported one update late, settled by what the next update saw (fixed-lag smoothing).

The online tracker decides at each update who is there from that update and the past alone. Two
of its decisions the very next update settles:

- **A new person's first sighting.** A track is tentative until its ``activate_hits``-th
  detection, so the online output misses every person's first update (or first few). A tentative
  track matched at update k and confirmed at k + 1 was a person at k: it is reported at k, at
  its position then, under the id it got at k + 1.
- **A missed update.** A confirmed track missed at k (its person hidden, or their box dropped)
  and matched again at k + 1 was there at k: it is reported at k between its positions at k − 1
  and k + 1 (linear in time, which at 2 frames per second is nearer the truth than the
  prediction from k − 1 alone). One missed at k and not matched at k + 1 is not reported at k:
  its person has more likely left or never was.

Everything matched at k is reported as the online tracker reported it. Nothing else changes:
ids, positions of matched tracks and the tracker's own state are the online tracker's.

The price is one update of delay, so live alerts keep the online output; the settled one suits
what is read after the fact and offline evaluation, and matters most at low frame rates. On
WILDTRACK (2 frames per second, ``docs/RESULTS.md``) it raised tracked MODA 0.895 → 0.916 and
IDF1 0.863 → 0.871 (noise seed 0). The live services publish the online output only.

>>> import numpy as np
>>> from bevflow.detections import Cylinders
>>> from bevflow.tracking.tracker import Tracker, TrackerConfig
>>> tracker, settled, frames = Tracker(TrackerConfig(activate_hits=2)), SettledTracks(), []
>>> for t in (0.0, 0.5, 1.0):
...     online = tracker.update(Cylinders(xy=np.array([[t, 0.0]])), t)
...     frames.append(settled.push(tracker.tracks(include_tentative=True), t))
>>> frames.append(settled.flush())  # the last update, with nothing after it to settle it
>>> [(f.time_s, f.tracks.id.tolist()) for f in frames if f is not None]  # online, 0.0 s had nobody
[(0.0, [1]), (0.5, [1]), (1.0, [1])]
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from bevflow.tracking.tracker import TrackTable

BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class SettledFrame:
    """The tracks of the update at ``time_s``, as the next update settled them."""

    time_s: float
    tracks: TrackTable


@dataclass(frozen=True)
class _Update:
    time_s: float
    tracks: TrackTable  # every live track after the update, tentative ones included


class SettledTracks:
    """Fixed-lag smoothing of one update over a tracker's output; see the module docstring."""

    def __init__(self) -> None:
        self._before: _Update | None = None
        self._pending: _Update | None = None

    def push(self, tracks: TrackTable, time_s: float) -> SettledFrame | None:
        """Take every live track after the update at ``time_s``
        (``Tracker.tracks(include_tentative=True)``) and return the update before it, settled;
        None for the first push."""
        update = _Update(float(time_s), tracks)
        settled = None if self._pending is None else self._settle(self._before, self._pending, update)
        self._before, self._pending = self._pending, update
        return settled

    def push_each(self, updates: list[tuple[float, TrackTable]]) -> list[TrackTable]:
        """``push`` each (time, tracks) of ``updates`` in turn (what a tracker made final:
        ``bevflow.tracking.hypotheses.final_updates``); the tracks of what they settled."""
        settled = (self.push(tracks, time_s) for time_s, tracks in updates)
        return [frame.tracks for frame in settled if frame is not None]

    def flush(self) -> SettledFrame | None:
        """The last update pushed, settled without a next one (its matched tracks only); None if
        there is none. The next push starts afresh."""
        settled = None if self._pending is None else self._settle(self._before, self._pending, None)
        self._before = self._pending = None
        return settled

    @staticmethod
    def _settle(before: _Update | None, now: _Update, after: _Update | None) -> SettledFrame:
        tracks = now.tracks
        matched = tracks.detection >= 0
        report = tracks.confirmed & matched
        xy, ids = tracks.xy.copy(), tracks.id.copy()
        if after is not None:
            later = after.tracks
            index = {k: i for i, k in enumerate(later.key.tolist())}
            at = np.array([index.get(k, -1) for k in tracks.key.tolist()], dtype=np.int64)
            # A track gone by then looks up the appended False (at −1).
            matched_after = np.append(later.detection >= 0, False)[at]
            confirmed_after = np.append(later.confirmed, False)[at]
            first = ~tracks.confirmed & matched & confirmed_after
            ids[first] = later.id[at[first]]
            report |= first
            if before is not None:
                report |= _bridge(before, now, after, at, tracks.confirmed & ~matched & matched_after, xy)
        return SettledFrame(now.time_s, replace(tracks[report], xy=xy[report], id=ids[report]))


def _bridge(
    before: _Update, now: _Update, after: _Update, at: NDArray[np.int64], missed: BoolArray, xy: NDArray[np.float64]
) -> BoolArray:
    """Which of the tracks ``missed`` at ``now`` were matched at ``before`` too; writes their
    position at ``now`` into ``xy``, interpolated in time between ``before`` and ``after``."""
    earlier = before.tracks
    matched_rows = np.flatnonzero(earlier.detection >= 0)
    row_of = dict(zip(earlier.key[matched_rows].tolist(), matched_rows.tolist(), strict=True))
    span = after.time_s - before.time_s
    w = (now.time_s - before.time_s) / span if span > 0 else 0.5
    bridged = np.zeros(len(missed), dtype=bool)
    for row in np.flatnonzero(missed):
        j = row_of.get(int(now.tracks.key[row]))
        if j is not None:
            start, end = earlier.xy[j], after.tracks.xy[at[row]]
            xy[row] = start + w * (end - start)
            bridged[row] = True
    return bridged
