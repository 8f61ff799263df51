"""Where identities are lost: each annotated person's frames, by the track id that followed them.

IDF1 counts the frames in which a person is followed under the one id paired with them. This says
what happened in the others, which is where a tracker is to be mended. Each frame's people are
matched one to one to the tracks within the threshold (least total distance,
``bevflow.metrics.matching.match_positions``), and a person's *main* id is the one that followed
them in most of their frames. Every other frame of theirs is

- ``unmatched``: no track within the threshold (a miss), or
- in a *run*, consecutive frames of theirs under one other id, by the run's length: ``flicker``
  (1 to ``FLICKER_FRAMES``), ``short`` (up to ``SHORT_FRAMES``) or long, and a long run is
  - ``fresh`` where its id had followed nobody else before the run: a new track after the
    person's own was lost, or a second track of theirs;
  - ``taken`` where it had: tracks swapped, or one left its person for this one.

Long fresh runs point at lost tracks (gates, coasting, the lost pass); long taken runs at tracks
that swap in a crowd (association, false points beside people). On CMC2 (``docs/RESULTS.md``) the
two are about equal.

>>> import numpy as np
>>> one = (np.array([1]), np.array([[0.0, 0.0]]))
>>> b = identity_breakdown([one] * 3, [(np.array([7]), np.zeros((1, 2)))] * 2 + [(np.array([8]), np.zeros((1, 2)))])
>>> b.main, b.flicker, b.people[0].ids
(2, 1, (7, 8))
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from bevflow.metrics.matching import match_positions
from bevflow.metrics.tracking import Frame

FLICKER_FRAMES = 3
SHORT_FRAMES = 10
NOBODY = -1  # the id of a frame in which no track followed the person


@dataclass(frozen=True)
class PersonIdentities:
    """One person: frames present, the main id (``NOBODY`` if never followed) and its frames, and
    every id that followed them, in the order they first did."""

    person: int
    frames: int
    main_id: int
    main: int
    ids: tuple[int, ...]


@dataclass(frozen=True)
class IdentityBreakdown:
    """Person-frames by what followed them (module docstring); the counts add up to
    ``person_frames``."""

    person_frames: int
    main: int
    unmatched: int
    flicker: int
    short: int
    long_fresh: int
    long_taken: int
    people: tuple[PersonIdentities, ...]

    def share(self, count: int) -> float:
        """``count`` as a fraction of the person-frames (NaN without any)."""
        return count / self.person_frames if self.person_frames else float("nan")

    def as_dict(self) -> dict[str, Any]:
        counts = {k: v for k, v in asdict(self).items() if k != "people"}
        return counts | {"people": [asdict(p) | {"ids": list(p.ids)} for p in self.people]}


def identity_breakdown(
    gt_frames: Sequence[Frame], hyp_frames: Sequence[Frame], threshold_m: float = 0.5
) -> IdentityBreakdown:
    """Each person's frames in ``gt_frames`` by the track of ``hyp_frames`` (the same instants,
    each an ``(ids, xy)`` pair) that followed them within ``threshold_m``."""
    if len(gt_frames) != len(hyp_frames):
        raise ValueError(f"gt_frames has {len(gt_frames)} frames but hyp_frames has {len(hyp_frames)}")
    people, followers = _follow(gt_frames, hyp_frames, threshold_m)
    counts = dict.fromkeys(("main", "unmatched", "flicker", "short", "long_fresh", "long_taken"), 0)
    for person in people:
        for kind, frames in person.runs(followers):
            counts[kind] += frames
    summaries = tuple(p.summary() for p in people)
    return IdentityBreakdown(person_frames=sum(p.frames for p in summaries), people=summaries, **counts)


def _follow(
    gt_frames: Sequence[Frame], hyp_frames: Sequence[Frame], threshold_m: float
) -> tuple[list[_PersonTrack], dict[int, list[tuple[int, int]]]]:
    """Each person's frames and the id that followed them in each, and for each id the (frame
    index, person) pairs it followed."""
    people: dict[int, _PersonTrack] = {}
    followers: dict[int, list[tuple[int, int]]] = {}
    for k, ((gt_ids, gt_xy), (hyp_ids, hyp_xy)) in enumerate(zip(gt_frames, hyp_frames, strict=True)):
        tracks = np.full(len(gt_ids), NOBODY, dtype=np.int64)
        if len(gt_ids) and len(hyp_ids):
            gt_idx, hyp_idx, _ = match_positions(gt_xy, hyp_xy, threshold_m)
            tracks[gt_idx] = np.asarray(hyp_ids)[hyp_idx]
        for person, track in zip(np.asarray(gt_ids).tolist(), tracks.tolist(), strict=True):
            followed = people.setdefault(person, _PersonTrack(person, [], []))
            followed.ids.append(track)
            followed.frames.append(k)
            if track != NOBODY:
                followers.setdefault(track, []).append((k, person))
    return list(people.values()), followers


@dataclass(frozen=True)
class _PersonTrack:
    """One person's frames, gathered in order, and the id that followed them in each."""

    person: int
    ids: list[int]  # the id that followed them in each of their frames
    frames: list[int]  # those frames' indices

    @property
    def main_id(self) -> int:
        followed = [i for i in self.ids if i != NOBODY]
        if not followed:
            return NOBODY
        values, counts = np.unique(followed, return_counts=True)
        return int(values[np.argmax(counts)])  # the smallest id among equals: reproducible

    def summary(self) -> PersonIdentities:
        main = self.main_id
        order = tuple(dict.fromkeys(i for i in self.ids if i != NOBODY))
        return PersonIdentities(self.person, len(self.ids), main, self.ids.count(main) if main != NOBODY else 0, order)

    def runs(self, followers: dict[int, list[tuple[int, int]]]) -> list[tuple[str, int]]:
        """(kind, frames) of each run of one id in this person's frames."""
        main, out = self.main_id, []
        start = 0
        for end in range(1, len(self.ids) + 1):
            if end < len(self.ids) and self.ids[end] == self.ids[start]:
                continue
            track, length = self.ids[start], end - start
            if track == NOBODY:
                out.append(("unmatched", length))
            elif track == main:
                out.append(("main", length))
            elif length <= FLICKER_FRAMES:
                out.append(("flicker", length))
            elif length <= SHORT_FRAMES:
                out.append(("short", length))
            else:
                first = self.frames[start]
                taken = any(k < first and other != self.person for k, other in followers[track])
                out.append(("long_taken" if taken else "long_fresh", length))
            start = end
        return out
