"""Companions: people who came in together, whose closeness is no incident.

A family, a couple or colleagues walk in together and stay within arm's length for as long as they
are in the hall. Every such group is a distance violation for as long as it stays, and in a busy
hall they made most distance incidents (the demo hall, 15 minutes: 87 incidents, 6 a minute,
with the simulator's true identities), each asking a supervisor to look at people who did nothing
unusual.

A pair of track ids are **companions** when they were already close (in violation) within
``window_s`` of the younger one's first sighting, and then stayed close for at least
``COMPANION_SHARE`` of the ticks over the following ``window_s``: they arrived together. Two
strangers who meet later in the hall are never companions, however long they stand together;
that is exactly what an incident is for. A pair still being judged (its first ``window_s``)
counts as companions, so an incident never opens on a family in the seconds before the rule has
seen enough of them; ``window_s`` is far below the time an incident takes to open
(``incident_min_duration_s``), so strangers lose nothing by the wait.

The price: a person whose track is lost and found again in the middle of the hall starts a new
id beside whoever they stand next to, and so becomes that person's companion. With the
trackers' identity churn on real input this hides some closeness between strangers; the
violations themselves (``DistanceMonitor``, the daily report) still count every pair.

>>> c = Companions(window_s=2.0)
>>> for t in range(6):  # 1 and 2 arrive together; 3 appears at t=0 and meets 1 only at t=4
...     pairs = [[1, 2]] + ([[1, 3]] if t >= 4 else [])
...     c.update(t * NS_PER_S, [1, 2, 3], pairs)
>>> c.are_companions(1, 2), c.are_companions(1, 3)
(True, False)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bevflow.analytics.positions import seconds_to_ns
from bevflow.units import NS_PER_S

COMPANION_SHARE = 0.8  # of the judging window's ticks a pair must spend close
FORGET_S = 10.0  # an id unseen this long is forgotten (its track has ended)


@dataclass
class _Pair:
    judged_until_ns: int  # the end of the pair's judging window
    ticks: int = 0  # ticks in the window with both present
    close: int = 0  # of those, ticks the pair was close
    companions: bool | None = None  # None while being judged


class Companions:
    """Which close pairs arrived together (module docstring). ``window_s`` 0 turns the rule off."""

    def __init__(self, window_s: float) -> None:
        self.window_ns = seconds_to_ns(window_s)
        self._first_seen: dict[int, int] = {}
        self._last_seen: dict[int, int] = {}
        self._pairs: dict[tuple[int, int], _Pair] = {}
        self._judging: set[tuple[int, int]] = set()

    def update(self, time_ns: int, ids: ArrayLike, pairs: ArrayLike) -> None:
        """Advance to ``time_ns`` with the tick's track ids and its (K, 2) close pairs."""
        if self.window_ns <= 0:
            return
        t = int(time_ns)
        present = [int(i) for i in np.asarray(ids).reshape(-1).tolist()]
        for i in present:
            self._first_seen.setdefault(i, t)
            self._last_seen[i] = t
        close = {(min(a, b), max(a, b)) for a, b in np.asarray(pairs, dtype=np.int64).reshape(-1, 2).tolist()}
        for key in close - self._pairs.keys():
            arrived = max(self._first_seen.get(key[0], t), self._first_seen.get(key[1], t))
            if t - arrived <= self.window_ns:
                self._pairs[key] = _Pair(judged_until_ns=t + self.window_ns)
                self._judging.add(key)
            else:
                self._pairs[key] = _Pair(judged_until_ns=t, companions=False)
        self._judge(t, set(present), close)
        self._forget(t)

    def are_companions(self, a: int, b: int) -> bool:
        """True for a pair that arrived together, or is still being judged."""
        pair = self._pairs.get((min(a, b), max(a, b)))
        return pair is not None and pair.companions is not False

    def strangers(self, pairs: ArrayLike) -> NDArray[np.int64]:
        """The rows of (K, 2) ``pairs`` that are not companions."""
        rows: NDArray[np.int64] = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        if self.window_ns <= 0 or not len(rows):
            return rows
        keep = np.array([not self.are_companions(a, b) for a, b in rows.tolist()], dtype=bool)
        strangers: NDArray[np.int64] = rows[keep]
        return strangers

    def _judge(self, t: int, present: set[int], close: set[tuple[int, int]]) -> None:
        for key in list(self._judging):
            pair = self._pairs[key]
            if key[0] in present and key[1] in present:
                pair.ticks += 1
                pair.close += key in close
            if t >= pair.judged_until_ns:
                pair.companions = pair.ticks > 0 and pair.close >= COMPANION_SHARE * pair.ticks
                self._judging.discard(key)

    def _forget(self, t: int) -> None:
        horizon = t - int(FORGET_S * NS_PER_S)
        gone = {i for i, seen in self._last_seen.items() if seen < horizon}
        if not gone:
            return
        for i in gone:
            del self._first_seen[i], self._last_seen[i]
        self._pairs = {k: p for k, p in self._pairs.items() if k[0] not in gone and k[1] not in gone}
        self._judging &= self._pairs.keys()
