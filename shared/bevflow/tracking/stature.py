"""Each track's head height, weighed in every pair it may make (``bevflow.tracking.tracker``).

The projector reads a person's head height off each box where the box can measure it
(``bevflow.stature``, ``Cylinders.stature``); fusion gives a person the mean of their views'
(``bevflow.fusion``). Each track keeps its height from what it took (``fused_stature``), and a
pair costs more by the log-likelihood ratio of the detection's height given the track's against
given anyone's, at most ``STATURE_COST_CAP`` (``stature_cost``). Two people passing each other
at 0.2 m are told apart by a tenth of a metre of height where their motion says nothing.

Measured on CMC2 (``docs/RESULTS.md``), online MOTA / IDF1 on the recording and the mean of its
twelve perturbed copies: fused first 0.878 / 0.662 → 0.882 / 0.716 and copies 0.878 / 0.606 →
0.882 / 0.628 (36 copies: IDF1 0.590 → 0.619); with the tracks taking the views
(``bevflow.tracking.views``) 0.891 / 0.731 → 0.921 / 0.835 and copies 0.895 / 0.718 → 0.894 /
0.751 (36 copies: IDF1 0.715 → 0.749).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

STATURE_STD_M = 0.05
"""One view's error in a person's head height (``Cylinders.stature``): CMC2's people, one at a
time, spread 0.02–0.14 m between quartiles. At 0.08 m the cue gained a third as much with views;
fused first, 0.035 / 0.05 / 0.07 m gave the twelve copies IDF1 0.634 / 0.628 / 0.618."""

STATURE_DRIFT_M = 0.02
"""How much a track's head height may drift in a second (m/√s): people stoop, sit and stand."""

ANYONE_STATURE_M = (1.70, 0.08)
"""Mean and spread of anyone's head height, m: what a view's height is weighed against."""

STATURE_COST_CAP = 2.0
"""The most a height that does not fit may add to a pair's cost. Uncapped, the cue cost CMC2's
copies 0.013 MOTA: a height read off a box cut short can break a right pair. Capped at 2 (or
0.5) it kept MOTA and gained more IDF1 (36 copies: 0.032 against 0.022). Fused first, caps
1 / 2 / 3 gave the twelve copies IDF1 0.623 / 0.628 / 0.627."""


def stature_cost(view: FloatArray, track: FloatArray, track_variance: FloatArray) -> FloatArray:
    """What a view's head height adds to its pair with a track: the negative log-likelihood ratio
    of that height given the track's against given anyone's, at most ``STATURE_COST_CAP``; 0
    where either height is unknown (NaN), so a track yet unmeasured is neither helped nor hurt."""
    if not np.isfinite(view).any():  # a site whose cameras measure no height (ceilings)
        return np.zeros(np.broadcast(view, track, track_variance).shape)
    mean, spread = ANYONE_STATURE_M
    pair = STATURE_STD_M**2 + track_variance
    anyone = STATURE_STD_M**2 + spread**2
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = (view - track) ** 2 / pair + np.log(pair / anyone) - (view - mean) ** 2 / anyone
    return np.where(np.isfinite(ratio), np.minimum(ratio, STATURE_COST_CAP), 0.0)


def fused_stature(track: FloatArray, track_variance: FloatArray, view: FloatArray, owner: IntArray) -> tuple[FloatArray, FloatArray]:
    """Each track's head height (NaN: unknown, variance inf) updated with the measured heights of
    the views it took (``owner``: each view's track row; NaN views measure nothing)."""
    measured = np.isfinite(view)
    count = np.bincount(owner[measured], minlength=len(track)).astype(np.float64)
    total = np.bincount(owner[measured], weights=view[measured], minlength=len(track))
    known = np.isfinite(track)
    prior = np.where(known, 1.0 / track_variance, 0.0)
    information = prior + count / STATURE_STD_M**2
    hit = count > 0
    stature, variance = track.copy(), track_variance.copy()
    stature[hit] = (np.where(known, track * prior, 0.0)[hit] + total[hit] / STATURE_STD_M**2) / information[hit]
    variance[hit] = 1.0 / information[hit]
    return stature, variance
