from __future__ import annotations

import numpy as np
import pytest

from bevflow.evaluation.identities import FLICKER_FRAMES, NOBODY, SHORT_FRAMES, identity_breakdown

A, B = np.array([0.0, 0.0]), np.array([3.0, 0.0])  # where people 1 and 2 stand, far apart


def frames(*followers: tuple[int, int]) -> tuple[list, list]:
    """Truth and tracks of people 1 and 2, one frame per (id following person 1, id following
    person 2); ``NOBODY``: no track there."""
    gt, hyp = [], []
    for first, second in followers:
        gt.append((np.array([1, 2]), np.stack([A, B])))
        here = [(i, xy) for i, xy in ((first, A), (second, B)) if i != NOBODY]
        hyp.append((np.array([i for i, _ in here], dtype=np.int64), np.array([xy for _, xy in here]).reshape(-1, 2)))
    return gt, hyp


LONG = SHORT_FRAMES + 1
CASES = {
    "followed throughout": ([(7, 8)] * 20, dict(main=40)),
    "missed": ([(7, 8)] * 18 + [(NOBODY, 8)] * 2, dict(main=38, unmatched=2)),
    "a neighbour's id for a frame or two": ([(7, 8)] * 18 + [(8, 7)] * 2, dict(main=36, flicker=4)),
    "a few frames under another id": ([(7, 8)] * 15 + [(9, 8)] * 5, dict(main=35, short=5)),
    "lost, then a new track": ([(7, 8)] * 15 + [(NOBODY, 8)] * 2 + [(9, 8)] * LONG,
                               dict(main=15 + 17 + LONG, unmatched=2, long_fresh=LONG)),
    "swapped": ([(7, 8)] * 20 + [(8, 7)] * LONG, dict(main=40, long_taken=2 * LONG)),
    "a track that followed someone else for a moment": ([(7, 9)] * 2 + [(7, 8)] * 18 + [(9, 8)] * LONG,
                                                         dict(main=20 + 18 + LONG, flicker=2, long_taken=LONG)),
    "a person's own second track, back": ([(7, 8)] * 15 + [(9, 8)] * 2 + [(7, 8)] * 3 + [(9, 8)] * LONG,
                                          dict(main=18 + 20 + LONG, flicker=2, long_fresh=LONG)),
}


@pytest.mark.parametrize(("followers", "expected"), CASES.values(), ids=CASES.keys())
def test_each_persons_frames_are_counted_by_what_followed_them(followers: list, expected: dict) -> None:
    got = identity_breakdown(*frames(*followers))
    counts = {k: getattr(got, k) for k in ("main", "unmatched", "flicker", "short", "long_fresh", "long_taken")}
    assert counts == dict.fromkeys(counts, 0) | expected
    assert sum(counts.values()) == got.person_frames == 2 * len(followers)


@pytest.mark.parametrize(("length", "kind"), [(FLICKER_FRAMES, "flicker"), (FLICKER_FRAMES + 1, "short"),
                                              (SHORT_FRAMES, "short"), (SHORT_FRAMES + 1, "long_fresh")])
def test_runs_are_told_apart_by_their_length(length: int, kind: str) -> None:
    got = identity_breakdown(*frames(*([(7, 8)] * 20 + [(9, 8)] * length)))
    assert getattr(got, kind) == length


def test_people_keep_their_ids_in_order_of_first_use() -> None:
    got = identity_breakdown(*frames(*([(7, 8)] * 5 + [(9, 8)] * 2 + [(7, 8)] * 5)))
    first = got.people[0]
    assert (first.person, first.frames, first.main_id, first.main, first.ids) == (1, 12, 7, 10, (7, 9))
    assert got.as_dict()["people"][0] == {"person": 1, "frames": 12, "main_id": 7, "main": 10, "ids": [7, 9]}
    assert got.as_dict()["long_fresh"] == 0 and got.share(got.main) == pytest.approx(22 / 24)


def test_a_person_never_followed_has_no_main_id_and_no_frames_give_no_share() -> None:
    got = identity_breakdown(*frames(*[(NOBODY, 8)] * 3))
    assert (got.people[0].main_id, got.people[0].main, got.unmatched) == (NOBODY, 0, 3)
    nothing = identity_breakdown([], [])
    assert nothing.person_frames == 0 and np.isnan(nothing.share(0))


def test_truth_and_tracks_must_have_the_same_frames() -> None:
    with pytest.raises(ValueError, match="1 frames but hyp_frames has 2"):
        identity_breakdown(frames((7, 8))[0], frames((7, 8), (7, 8))[1])
