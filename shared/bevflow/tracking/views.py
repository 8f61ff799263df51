"""Tracks that take each camera's views themselves, before any fusion (``TrackerConfig.track_views``).

Fusing first (``bevflow.fusion``) decides which views are one person from one instant alone. In a
crowd that is where identities are lost: two people 0.5 m apart in a line from a side camera give
it one box, or two whose feet land between them, and the fused point is wrong in a way that
lasts several frames (on CMC2 the fused points' errors are correlated 0.4–0.55 from one frame to
the next). The tracks know more: where each person is expected now. So in this mode every camera's
views (the projector's cylinders, each with its feet covariance) go to the tracker as they are:

- **Slots.** Each track has one slot per camera, and a view may go only to its own camera's slot
  of a track, so a camera gives a person at most one view and a person may be seen by every camera
  at once. Matching views to slots is one assignment problem (``slot_rows``), solved, ranked and
  held open by hypotheses as the fused people are in the other mode, tentative tracks included.
- **Costs.** A pair costs its negative log-likelihood d² + ln |S| (S the track's predicted feet
  covariance plus the view's), within the tracker's χ² gate; a tentative track's slot costs
  ``TENTATIVE_COST`` more, so a confirmed track takes a contested view. In the solve a view or a
  slot left over costs ``leftover_cost``; between hypotheses only the views left over count, since
  a camera often cannot see a person a track follows.
- **Update.** A track that took views is corrected once with their information-weighted mean
  (``fuse_views``): a side camera's view is long along its line of sight and counts mostly across
  it, so two cameras at right angles pin the feet.
- **Births.** Only the strong views that no track took are fused among themselves (the tracker's
  ``fuse``, ``bevflow.fusion`` without priors), and a fused point starts a tentative track only
  outside the gate of every track that took a view in this update: a second box of someone
  already followed starts nobody. A fixed distance instead (0.6 m, as good on CMC2) held back
  the track of someone 0.5 m from a neighbour under a ceiling camera, whose views are precise: the
  paper suite's short run of sequence 3 lost MOTA 0.894 → 0.833.
- **Heights.** A view whose box measured the person's head height weighs it in each pair it may
  make, as fused people do in the other mode (``bevflow.tracking.stature``); each track keeps
  its height from the views it took.

Measured on CMC2's twelve perturbed copies (``docs/RESULTS.md``, 20 hypotheses), online: views
fused first IDF1 0.606, MOTA 0.878; views taken by the tracks 0.718, 0.895, with more false tracks
and fewer misses (precision 0.959 → 0.929, recall 0.945 → 0.986); with heights 0.751, 0.894 (on
36 copies 0.715 → 0.749, and the recording 0.731 → 0.835). Under the paper suite's ceiling
fisheyes the false tracks cost more: with the shipped detectors two rows failed their targets
(seq 5's pair F1 0.976 → 0.933, seq 6 MOTA 0.903 → 0.892). Seq 6 has one camera, so it is not two
cameras disagreeing; frame by frame it left 32 false and 142 missed tracks against 16 and 140
fused first, from births going wrong both ways:

- held back: a person standing 0.48 m from a tracked neighbour started no track, being inside
  that track's gate; two frames later the neighbour's box was missed, the neighbour's track took
  the person's box, and the neighbour came back under a new id (frames 173–179);
- let through: after a frame with two boxes of one walking person, their feet 0.01 m apart, a
  second track followed that person beside the first (frames 201–210).

None of these changed it for the better: letting a camera's second view start a track whatever
the gate (a camera shows a person once; seq 6 false tracks 32 → 52, CMC2 IDF1 0.731 → 0.621),
letting a slot take a view within fusion's 0.45 m beyond the gate, or dropping a leftover view
within 0.45–0.6 m of a view its camera gave a track.

**Which sites take views** (``side_views_only``, a site's ``track_views`` left unset): those whose
cameras all look more than ``SIDE_VIEW_DEG`` away from straight down. Under side cameras a fused
point of one instant is often wrong (the case above), and with views a track that took none is
seen by no camera, so it is not reported while it coasts (``TrackerConfig.from_thresholds``);
under a ceiling camera views are precise, and fusing first held the paper suite's rows. Each way on
the same data (replay command, docs/RESULTS.md), fused first against views:

- CMC2 (four side cameras, a real detector): MOTA / IDF1 0.930 / 0.744 against 0.925 / 0.836;
  its twelve perturbed copies 0.910 / 0.707 against 0.899 / 0.753.
- WILDTRACK's noisy annotated boxes in the replay layout (seven side cameras, 2 fps, seeds 0–2):
  MOTA 0.705, 0.693, 0.686 against 0.683, 0.680, 0.693; IDF1 0.760, 0.760, 0.762 against 0.755,
  0.756, 0.767. Reporting a track that took no view, as the other mode reports a missed one,
  views scored MOTA 0.643, 0.634, 0.658: on seed 0, 273 of 362 such reports lay where nobody stood.

Cost, ``bevflow bench --only tracking`` at 10 fps, once each way in one session on a 2-core AMD
EPYC: a tick for 100 people on 4 / 16 / 64 cameras took 35 / 28 / 23 ms with views against
33 / 28 / 12 ms fused first, and for 1,000 people on 16 / 64 cameras 22 / 24 against 33 / 22 ms
(the tick's own fusion needs no priors with views).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from bevflow.matrix2 import inverse

if TYPE_CHECKING:  # only the cameras' poses are read
    from bevflow.camera import Camera

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

TENTATIVE_COST = 2.0
"""Added to a pair with a tentative track: between a confirmed and a tentative track a view goes to
the confirmed one unless the tentative one is e² times likelier. In a first version of this mode,
0 and 4 scored alike on CMC2's twelve perturbed copies (IDF1 0.705 and 0.730 against 0.697)."""

LEFTOVER_LOG_DET = -3.0
"""ln |S| of the least likely pair worth making at the gate's edge, which prices a view left over
(``leftover_cost``): about 0.47 m per axis, wider than the filter's own noise because a side
camera's view is long along its line of sight. In a first version of this mode, −5 and −1 scored
alike on CMC2's copies (IDF1 0.720 and 0.709 against 0.697)."""


SIDE_VIEW_DEG = 45.0
"""A camera whose optical axis lies more than this from straight down is a side view. The side
cameras measured lie 60–81° from it (CMC2, WILDTRACK), ceiling fisheyes at 0°."""


def side_views_only(cameras: Sequence[Camera]) -> bool:
    """Whether every one of ``cameras`` is a side view (``SIDE_VIEW_DEG``): where a site that
    leaves ``track_views`` unset takes views (module docstring). False for no cameras."""
    if not cameras:
        return False
    return all(camera.tilt_deg > SIDE_VIEW_DEG for camera in cameras)


def leftover_cost(gate_chi2: float) -> float:
    """What a view left over costs (half the cost of a pair at the gate's edge whose ln |S| is
    ``LEFTOVER_LOG_DET``): a pair is made only where it costs less than two leftovers."""
    return 0.5 * (gate_chi2 + LEFTOVER_LOG_DET)


def slot_rows(track: IntArray, camera: IntArray, n_cameras: int) -> IntArray:
    """The slot of each (track, view of ``camera``) pair: one row per track and camera."""
    return track * n_cameras + camera


def fuse_views(xy: FloatArray, covariance: FloatArray, owner: IntArray, n_tracks: int) -> tuple[IntArray, FloatArray, FloatArray]:
    """Each track's views (``owner``: the track of each view) fused by their information: the
    tracks that took any, their fused feet (k, 2) and its covariance (k, 2, 2)."""
    information = inverse(covariance)
    total = np.zeros((n_tracks, 2, 2))
    np.add.at(total, owner, information)
    weighted = np.zeros((n_tracks, 2))
    np.add.at(weighted, owner, np.einsum("nij,nj->ni", information, xy))
    hit = np.unique(owner)
    fused_covariance = inverse(total[hit])
    return hit, np.einsum("nij,nj->ni", fused_covariance, weighted[hit]), fused_covariance
