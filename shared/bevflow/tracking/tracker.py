"""The one world tracker: every person on the site, from fused floor cylinders (paper 3.7).

Each ``update(cylinders, time_s)`` runs, for all tracks at once:

1. **predict** every track to ``time_s`` with a constant-velocity Kalman filter;
2. **associate** detections to tracks by feet distance, gated by distance and by each track's
   uncertainty (``gate_chi2``): confirmed tracks take the strong detections first, then
   tentative tracks take what is left, then confirmed tracks still unmatched may take a weak
   (low-score) detection within a tighter gate (ByteTrack's second pass: a person half hidden
   still continues their track, but never starts one), and last a strong detection nobody took
   within a distance they could have walked (``lost_speed_mps``), past the uncertainty gate;
3. **update** the matched tracks (Kalman on the feet, moving averages on height and radius);
4. **birth** a tentative track for every strong detection left over;
5. **retire** confirmed tracks after ``max_misses`` consecutive misses, tentative ones after
   ``tentative_max_misses`` (a false positive that appears once dies before it could be
   confirmed).

A tentative track becomes confirmed after ``activate_hits`` associated detections and only then
gets an id, so ids are never spent on false positives. Ids are unique for the life of the
tracker (``reset()`` keeps counting) and ``first_id`` lets a restarted tracker continue after
the last id it published. There is no global state: two trackers never share anything.

Association cost is the Euclidean feet distance to the predicted position, as in the paper;
with the uncertainty gate (``gate_chi2``) it is the pair's negative log-likelihood instead,
d² + ln |S| (d² the Mahalanobis distance² under S, the track's position covariance plus the
detection's). By distance alone a vague detection beside a person (one camera's second box of
them, placed 0.5 m deep along its line of sight) takes their track from their own precise one by
lying nearer; ln |S| prefers the precise pair. On CMC2's six perturbed copies (docs/RESULTS.md)
IDF1 0.474 → 0.529, HOTA 0.466 → 0.509 and MOTA 0.858 → 0.862; the Mahalanobis distance² alone
lost (IDF1 0.465). Where a detection and a track both know the person's head height, the
pair's cost also weighs it (``bevflow.tracking.stature``). Each pass is solved exactly by
``bevflow.metrics.matching.assign_edges``: only pairs within the gate are considered (found
with a k-d tree), a pair with no rival is matched outright and the contested rest goes to one
sparse assignment solve, minimising the total cost plus the largest cost a gated pair could
have (``gate``, or χ² plus the spread of ln |S|) for every track and detection left over.
1,000 people therefore cost about 3 ms per update rather than a dense 1,000 × 1,000 Hungarian
solve.

Reported tracks: ``update`` returns the confirmed tracks matched in this update, and those
coasting (missed) for at most ``report_max_misses`` consecutive updates, at their predicted
position. Reporting a coasting track bridges a missed detection (occlusion, a detector miss):
fewer misses and fragmentations, at the price of a false positive where the person really left.
With ``coast_needs_sighting`` a coasting track is reported only where a camera still sees part
of someone (a *sighting*, ``bevflow.fusion``: a cut box on a side view that placed nobody)
within ``sighting_gate_chi2`` of its predicted feet: a person hidden behind another is still
reported, a track whose person has gone is not. One update of coasting scored best overall.
Against reporting matched tracks only, MOTA goes
0.885 → 0.969 at 10 fps and 0.781 → 0.804 at 2 fps on simulated walkers (0.1 people/m²,
10 % of detections missed, 0.1 m noise), and 0.773 → 0.799 on the WILDTRACK ground truth
(2 fps) given the same noise and misses. Two updates gain 0.006 more at 10 fps but lose 0.021
at 2 fps, where a coasting person has moved on by 0.6 m.

>>> tracker = Tracker(TrackerConfig(activate_hits=2))
>>> for t in (0.0, 0.1, 0.2):
...     tracks = tracker.update(Cylinders(xy=np.array([[1.0 + t, 2.0]])), t)
>>> tracks.id.tolist(), tracks.hits.tolist()
([1], [3])
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from bevflow.detections import Cylinders
from bevflow.matrix2 import determinant, mahalanobis2
from bevflow.metrics.matching import assign_edges, gated_pairs
from bevflow.metrics.ranked_matching import RankingMemo, ranked_matchings
from bevflow.tracking.kalman import ConstantVelocityKalman, smooth
from bevflow.tracking.stature import STATURE_DRIFT_M, fused_stature, stature_cost
from bevflow.tracking.views import TENTATIVE_COST, fuse_views, leftover_cost, side_views_only, slot_rows

if TYPE_CHECKING:  # the tracker reads a site's thresholds and cameras but needs no site to run
    from bevflow.camera import Camera
    from bevflow.site import Thresholds

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]
KEYS_REMEMBERED = 4096
"""Confirmed tracks whose id is remembered by their key (``_Numbering``), the oldest forgotten first."""

Fuse = Callable[[Cylinders], Cylinders]
"""Views of several cameras in, the people they place out (``Tracker``'s ``fuse``)."""


@dataclass(frozen=True)
class TrackerConfig:
    """Tracker settings. Distances in metres, speeds in m/s.

    - ``gate_m``: farthest a strong detection may be from a track's predicted feet.
    - ``activate_hits``: associated detections before a track is confirmed (paper: 3).
    - ``max_misses``: consecutive updates without a detection that retire a confirmed track
      (paper: 5); ``tentative_max_misses`` the same for tracks not yet confirmed.
    - ``weak_score``: detections scoring below it are weak: they may only continue a confirmed
      track, within ``weak_gate_m``. ``min_score``: detections below it are ignored.
    - ``process_noise`` (m²/s³), ``measurement_std_m``, ``initial_speed_std_mps``: the Kalman
      filter's noise (see ``bevflow.tracking.kalman``). The defaults scored best of a sweep on
      the WILDTRACK ground truth with 0.1 m of added noise and on simulated walkers at 2 and
      10 fps; 0.2 m also matches the paper's position error of fused cylinders (0.06–0.19 m).
    - ``shape_smoothing``: weight of a new measurement in the height and radius averages.
    - ``report_max_misses``: confirmed tracks missed in more consecutive updates than this are
      kept but not returned by ``update`` (0 returns only tracks matched in this update; a site
      whose tracks take the views gets 0, ``from_thresholds``).
    - ``confirm_multi_view``: a track born from a detection that several cameras agreed on
      (``Cylinders.camera == -1``) is confirmed at once: two views at one instant corroborate a
      person as well as a single view over ``activate_hits`` frames, and at 2 fps waiting costs a
      second of every new track. Off by default (the paper confirms every track the same way).
    - ``measurement_from_covariance``: a detection that carries its feet covariance
      (``Cylinders.covariance``; fusion gives every fused person one) updates the filter with it
      rather than with ``measurement_std_m``, so a precise ceiling view (about 0.1 m) is
      followed closely and a side view counts mostly across its line of sight. On the paper
      suite it lowered the tracked position error (seq5 cam1 0.121 → 0.105 m, seq1 pair 0.104 →
      0.089 m) at equal or better MOTA; on WILDTRACK it raised MOTA on both noise seeds
      (0.847 → 0.851, 0.837 → 0.847) and moved IDF1 by −0.016 and +0.012.
    - ``gate_chi2``: a detection may also go to a track only within this Mahalanobis distance²
      of its predicted feet, under the track's position covariance plus the detection's
      (9.21: 99 % of χ²(2)); None gates by ``gate_m`` alone. A fixed 1.5 m gate lets a track whose
      person was missed take a neighbour's detection 1.3 m away, and the neighbour's track the
      next one along, a chain of swaps: with a person's detection missed one time in ten and
      exact positions otherwise, the CMC2 truth tracked with 66 identity switches by distance
      alone and 3 with this gate. It follows the frame rate by itself: the prediction's
      covariance grows with the time since the last update. With it, pairs are costed by their
      likelihood instead of their distance (module docstring). On real CMC2 boxes, every box kept
      and with distance costs (and fusion's track priors), MOTA 0.721 → 0.833, IDF1 0.344 →
      0.537 (``docs/RESULTS.md``). On WILDTRACK at 2 fps it gains IDF1 and loses MOTA
      (``bevflow.evaluation.wildtrack_tracking``), so ``WILDTRACK_TRACKER`` gates by distance
      alone.
    - ``lost_speed_mps``: after the gated passes, a confirmed track still without a detection may
      take a strong detection nobody took within this speed times the time since the last update
      (at most ``gate_m``). ``gate_chi2`` shrinks with the filter's uncertainty, so where positions
      are precise it refuses a person's own detection when they turn or stop (CMC2's truth with
      0.02 m of noise: IDF1 0.45, 78 identity switches); what is left over after every track had
      its pick is no neighbour's detection. 2 m/s (0.5 m at 4 fps) brings that to 0.78–0.92 (2–11
      switches) and leaves the real CMC2 boxes as they were (``docs/RESULTS.md``). None: no such pass.
    - ``hypotheses``: how many ways of matching are held open (``bevflow.tracking.hypotheses``;
      1: each update decides at once, this class alone), for ``hypothesis_window_s`` seconds
      before the likeliest one's decisions are final. More than 1 needs ``gate_chi2``.
    - ``track_views``: ``update`` takes each camera's views as they are (``Cylinders.camera`` the
      camera's index), not fused detections: every track takes at most one view from each camera
      and is corrected with those it took, and only the strong views no track took are fused (by
      the tracker's ``fuse``) to start tracks outside the gate of every track that took a view
      (``bevflow.tracking.views``). Weak views are matched with the strong ones in one pass (they
      still start nothing); a confirmed track that took no view may then take a strong one left
      over within ``lost_speed_mps``, as in the other mode. Needs ``gate_chi2``. A site that
      leaves its ``track_views`` unset takes views where every camera is a side view
      (``from_thresholds``).
    """

    gate_m: float = 1.5
    activate_hits: int = 3
    max_misses: int = 5
    tentative_max_misses: int = 2
    weak_score: float = 0.3
    weak_gate_m: float = 0.75
    min_score: float = 0.0
    process_noise: float = 0.3
    measurement_std_m: float = 0.2
    initial_speed_std_mps: float = 1.0
    shape_smoothing: float = 0.3
    report_max_misses: int = 1
    confirm_multi_view: bool = False
    measurement_from_covariance: bool = True
    coast_needs_sighting: bool = False
    sighting_gate_chi2: float = 9.21
    gate_chi2: float | None = 9.21
    lost_speed_mps: float | None = 2.0
    hypotheses: int = 1
    hypothesis_window_s: float = 2.0
    track_views: bool = False

    def __post_init__(self) -> None:
        if self.hypotheses > 1 and self.gate_chi2 is None:
            raise ValueError("TrackerConfig.hypotheses > 1 needs the uncertainty gate (gate_chi2)")
        if self.track_views and self.gate_chi2 is None:
            raise ValueError("TrackerConfig.track_views needs the uncertainty gate (gate_chi2)")
        if self.lost_speed_mps is not None and not self.lost_speed_mps > 0:
            raise ValueError(f"TrackerConfig.lost_speed_mps must be > 0 or None, got {self.lost_speed_mps}")
        names = ("gate_m", "weak_gate_m", "measurement_std_m", "initial_speed_std_mps", "sighting_gate_chi2",
                 "hypothesis_window_s")
        for name in names:
            if not getattr(self, name) > 0:
                raise ValueError(f"TrackerConfig.{name} must be > 0, got {getattr(self, name)}")
        for name in ("activate_hits", "max_misses", "tentative_max_misses", "hypotheses"):
            if getattr(self, name) < 1:
                raise ValueError(f"TrackerConfig.{name} must be >= 1, got {getattr(self, name)}")
        if self.process_noise < 0 or self.report_max_misses < 0:
            raise ValueError("TrackerConfig.process_noise and report_max_misses must be >= 0")
        if not 0 <= self.shape_smoothing <= 1:
            raise ValueError(f"TrackerConfig.shape_smoothing must be in [0, 1], got {self.shape_smoothing}")

    @classmethod
    def from_thresholds(cls, thresholds: Thresholds, cameras: Sequence[Camera] = (), **overrides: Any) -> TrackerConfig:
        """Settings from a site's ``Thresholds`` (track_gate_m, track_activate_hits,
        track_max_misses, track_hypotheses, track_views) and its ``cameras``: where track_views is
        unset, the tracks take the views when every camera is a side view
        (``bevflow.tracking.views.side_views_only``). With views a track that took none is seen by
        no camera, so it is not reported while it coasts (``report_max_misses`` 0). ``overrides``
        set any other field (checked as the fields are)."""
        views = side_views_only(cameras) if thresholds.track_views is None else thresholds.track_views
        site = cls(
            gate_m=thresholds.track_gate_m,
            activate_hits=thresholds.track_activate_hits,
            max_misses=thresholds.track_max_misses,
            hypotheses=thresholds.track_hypotheses,
            track_views=views,
            report_max_misses=0 if views else cls.report_max_misses,
        )
        return replace(site, **overrides)

    def kalman(self) -> ConstantVelocityKalman:
        return ConstantVelocityKalman(self.process_noise, self.measurement_std_m, self.initial_speed_std_mps)


@dataclass(frozen=True, eq=False)
class TrackTable:
    """Tracks as columns of equal length T.

    ``id`` (T,) (−1 while tentative), ``xy`` (T, 2) feet position and ``velocity`` (T, 2) from
    the filter, ``height`` and ``radius`` (T,) smoothed, ``hits`` (T,) associated detections so
    far, ``misses`` (T,) consecutive updates without one, ``age_s`` (T,) time since birth,
    ``detection`` (T,) index of the input cylinder that updated the track in this update or −1,
    ``confirmed`` (T,), ``key`` (T,) a number of the track's own from its birth, tentative or not,
    unique for the life of the tracker (``id`` is only given on confirmation; ``key`` follows a
    track through it, as ``bevflow.tracking.settled`` does)."""

    id: IntArray
    xy: FloatArray
    velocity: FloatArray
    height: FloatArray
    radius: FloatArray
    hits: IntArray
    misses: IntArray
    age_s: FloatArray
    detection: IntArray
    confirmed: BoolArray
    key: IntArray

    @classmethod
    def empty(cls) -> TrackTable:
        return cls(
            id=np.zeros(0, np.int64), xy=np.zeros((0, 2)), velocity=np.zeros((0, 2)), height=np.zeros(0),
            radius=np.zeros(0), hits=np.zeros(0, np.int64), misses=np.zeros(0, np.int64), age_s=np.zeros(0),
            detection=np.zeros(0, np.int64), confirmed=np.zeros(0, bool), key=np.zeros(0, np.int64),
        )  # fmt: skip

    def __len__(self) -> int:
        return len(self.id)

    def __getitem__(self, index: object) -> TrackTable:
        return TrackTable(**{f.name: getattr(self, f.name)[index] for f in fields(self)})


@dataclass(eq=False)
class _Tracks:
    """Every live track, tentative ones included (columns of equal length)."""

    id: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))
    state: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))
    covariance: FloatArray = field(default_factory=lambda: np.zeros((0, 4, 4)))
    height: FloatArray = field(default_factory=lambda: np.zeros(0))
    radius: FloatArray = field(default_factory=lambda: np.zeros(0))
    hits: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))
    misses: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))
    born_s: FloatArray = field(default_factory=lambda: np.zeros(0))
    detection: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))
    confirmed: BoolArray = field(default_factory=lambda: np.zeros(0, bool))
    key: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))
    stature: FloatArray = field(default_factory=lambda: np.zeros(0))  # head height, NaN unknown
    stature_variance: FloatArray = field(default_factory=lambda: np.zeros(0))

    def __len__(self) -> int:
        return len(self.id)

    def select(self, keep: BoolArray) -> _Tracks:
        return _Tracks(**{f.name: getattr(self, f.name)[keep] for f in fields(self)})

    def append(self, other: _Tracks) -> _Tracks:
        columns = {f.name: np.concatenate([getattr(self, f.name), getattr(other, f.name)]) for f in fields(self)}
        return _Tracks(**columns)

    def table(self, time_s: float) -> TrackTable:
        # Copies: the tracker updates its columns in place, a published table must not change.
        return TrackTable(
            id=self.id.copy(), xy=self.state[:, :2].copy(), velocity=self.state[:, 2:].copy(),
            height=self.height.copy(), radius=self.radius.copy(), hits=self.hits.copy(),
            misses=self.misses.copy(), age_s=time_s - self.born_s, detection=self.detection.copy(),
            confirmed=self.confirmed.copy(), key=self.key.copy(),
        )


@dataclass(frozen=True)
class _Candidates:
    """(track, detection) pairs one association pass may match, with their feet distance ``dist``
    (each pass's gate). Under the uncertainty gate also each pair's Mahalanobis distance² ``d2``,
    ln |S| of its innovation covariance (``log_det``), what the detection's head height adds
    (``height``, ``bevflow.tracking.stature``) and that gate's χ² (``chi2``)."""

    track: IntArray
    det: IntArray
    dist: FloatArray
    d2: FloatArray | None = None
    log_det: FloatArray | None = None
    chi2: float = 0.0
    height: FloatArray | None = None

    def cost(self, allowed: BoolArray, gate: float) -> tuple[FloatArray, float]:
        """The ``allowed`` pairs' costs and the worst cost a pair within the gate could have: the
        feet distance and ``gate``, or the negative log-likelihood d² + ln |S| (less the least
        ln |S|, so that no choice hangs on the unit of length) plus the height's term, and χ² plus
        the spread of ln |S|."""
        if self.d2 is None or self.log_det is None or self.height is None:
            return self.dist[allowed], gate
        log_det = self.log_det[allowed] - self.log_det[allowed].min()
        return self.d2[allowed] + log_det + self.height[allowed], self.chi2 + float(log_det.max())


@dataclass(frozen=True, eq=False)
class Choice:
    """One way to match the confirmed tracks to the strong detections of an update (its first
    pass): rows of the tracker's tracks, ``track``, take detections ``detection``. ``cost``: the
    negative log-likelihood of the whole pass (``Tracker.branch``)."""

    track: IntArray
    detection: IntArray
    cost: float


@dataclass(eq=False)
class _Numbering:
    """The next id and the next key, shared by a tracker and its copies (``Tracker.copy``), so
    that no two tracks of any of them ever get the same one. A track confirmed in two copies
    (hypotheses that matched it differently) is one track: it gets one id (``id_of``)."""

    next_id: int
    next_key: int = 0
    ids_by_key: dict[int, int] = field(default_factory=dict)

    def id_of(self, key: int) -> int:
        """The id of the track born as ``key``, given now if no copy has confirmed it yet."""
        if (known := self.ids_by_key.get(key)) is not None:
            return known
        self.ids_by_key[key], self.next_id = self.next_id, self.next_id + 1
        if len(self.ids_by_key) > KEYS_REMEMBERED:  # copies confirm a track within a few updates of each other
            for old in list(self.ids_by_key)[: KEYS_REMEMBERED // 2]:
                del self.ids_by_key[old]
        return self.ids_by_key[key]


@dataclass(frozen=True, eq=False)
class _Passes:
    """Which detections are strong and which weak, every (track, detection) pair within the
    wider distance gate (``near``), and those of them within the uncertainty gate (``pairs``; the
    same pairs where there is none)."""

    strong: BoolArray
    weak: BoolArray
    near: _Candidates
    pairs: _Candidates


class Tracker:
    """One online tracker for a whole site; see the module docstring."""

    def __init__(self, config: TrackerConfig | None = None, first_id: int = 1, fuse: Fuse | None = None) -> None:
        """``fuse``: how views left over are fused to start tracks, needed with ``track_views``
        (``bevflow.live.site_tracker`` passes ``bevflow.fusion`` with the site's cameras)."""
        self.config = config or TrackerConfig()
        if self.config.track_views and fuse is None:
            raise ValueError("TrackerConfig.track_views needs a fuse function to start tracks from the views left over")
        self._fuse = fuse
        self._kalman = self.config.kalman()
        self._numbering = _Numbering(int(first_id))
        self._tracks = _Tracks()
        self._time_s: float | None = None
        self._view_keys = np.zeros(0, np.int64)

    def copy(self) -> Tracker:
        """An independent tracker in the same state, numbering ids and keys from the same counter
        as this one: whatever either confirms later gets an id the other never gives."""
        twin = Tracker.__new__(Tracker)
        twin.config, twin._kalman, twin._numbering, twin._time_s = self.config, self._kalman, self._numbering, self._time_s
        twin._fuse, twin._view_keys = self._fuse, self._view_keys
        twin._tracks = _Tracks(**{f.name: getattr(self._tracks, f.name).copy() for f in fields(self._tracks)})
        return twin

    def __len__(self) -> int:
        """Live tracks, tentative ones included."""
        return len(self._tracks)

    @property
    def next_id(self) -> int:
        """The id the next confirmed track will get (pass it as ``first_id`` on restart)."""
        return self._numbering.next_id

    @property
    def time_s(self) -> float | None:
        """Time of the last update, None before the first."""
        return self._time_s

    def reset(self) -> None:
        """Forget every track and the clock; ids keep counting from where they were."""
        self._tracks = _Tracks()
        self._time_s = None

    def tracks(self, include_tentative: bool = False) -> TrackTable:
        """Every live track after the last update (confirmed ones, or all of them)."""
        tracks = self._tracks if include_tentative else self._tracks.select(self._tracks.confirmed)
        return tracks.table(self._time_s if self._time_s is not None else 0.0)

    def predicted(self, time_s: float, include_tentative: bool = False) -> Cylinders:
        """Where the confirmed tracks (or all) are expected at ``time_s``, as cylinders whose
        ``covariance`` is the filter's position covariance; the tracker itself is not moved.
        Fusion takes them as priors (``bevflow.fusion``, "Tracks as priors")."""
        tracks = self._tracks if include_tentative else self._tracks.select(self._tracks.confirmed)
        dt = 0.0 if self._time_s is None else max(0.0, float(time_s) - self._time_s)
        state, covariance = self._kalman.predict(tracks.state, tracks.covariance, dt)
        return Cylinders(xy=state[:, :2], height=tracks.height.copy(), radius=tracks.radius.copy(),
                         covariance=covariance[:, :2, :2].copy())

    def update(self, cylinders: Cylinders, time_s: float, sightings: Cylinders | None = None) -> TrackTable:
        """Advance to ``time_s`` (seconds, never decreasing) with the fused cylinders seen then,
        and return the confirmed tracks to report (see ``TrackerConfig.report_max_misses``).
        ``sightings``: views that placed nobody (``Fusion.sightings``, with covariances), used
        only by ``coast_needs_sighting``."""
        dt = self._predict(time_s)
        self._update(cylinders, time_s, dt, self._candidates(cylinders), None)
        return self.report(sightings)

    def view_keys(self) -> IntArray:
        """With ``track_views``: after an update, the ``key`` of the track each of its views went
        to, −1 for views no track took (the cameras that saw each track)."""
        return self._view_keys.copy()

    def branch(self, cylinders: Cylinders, time_s: float, count: int, within: float,
               memo: RankingMemo | None = None) -> Branches:  # fmt: skip
        """The ways this tracker may take an update, one per way of matching the confirmed tracks
        to the strong detections: the best and up to ``count`` − 1 runners-up costing at most
        ``within`` more (``bevflow.metrics.ranked_matching``). ``Branches.child`` makes the copy
        that took one (what it reports is its ``report``); this tracker is not moved. Choices are
        costed before any copy is made, so a caller keeping a few of many makes only those.

        Costed by negative log-likelihood (twice it, less constants): d² + ln |S| a pair (module
        docstring), and (``gate_chi2`` + ln |S₀|) / 2 a track or detection left over, S₀ the
        filter's own measurement covariance: a pair is worth making when it is likelier than one
        at the gate's edge with the filter's nominal noise. ``update``'s own first pass prices a
        leftover relative to the pairs at hand instead; these costs compare across trackers whose
        tracks differ. Needs the uncertainty gate (``gate_chi2``). ``memo``: rankings to share with
        the other trackers branching on the same update (``ranked_matchings``)."""
        chi2 = self.config.gate_chi2
        if chi2 is None:
            raise ValueError("Tracker.branch needs the uncertainty gate: TrackerConfig.gate_chi2 is None")
        moved = self.copy()
        dt = moved._predict(time_s)
        candidates = moved._candidates(cylinders)
        if self.config.track_views:
            choices = moved._view_choices(cylinders, candidates, chi2, count, within, memo)
        else:
            choices = moved._choices(len(cylinders), candidates, chi2, count, within, memo)
        return Branches(choices, moved, cylinders, float(time_s), dt, candidates)

    def _view_pairs(self, cylinders: Cylinders, candidates: _Passes, chi2: float) -> tuple[IntArray, IntArray, FloatArray, int]:
        """With ``track_views``: the (slot, view) pairs worth making and their costs, and how many
        cameras the slots are cut for (``bevflow.tracking.views``)."""
        pairs = candidates.pairs
        if pairs.d2 is None or pairs.log_det is None or pairs.height is None:
            raise ValueError("views are matched by the pairs' likelihoods (the uncertainty gate)")
        if len(cylinders) and cylinders.camera.min() < 0:
            raise ValueError("TrackerConfig.track_views takes each camera's views (camera >= 0), not fused detections")
        n_cameras = int(cylinders.camera.max()) + 1 if len(cylinders) else 1
        tentative = np.where(self._tracks.confirmed[pairs.track], 0.0, TENTATIVE_COST)
        cost = pairs.d2 + pairs.log_det + pairs.height + tentative
        usable = candidates.strong | candidates.weak
        keep = usable[pairs.det] & (cost < 2.0 * leftover_cost(chi2))
        rows = slot_rows(pairs.track[keep], cylinders.camera[pairs.det[keep]], n_cameras)
        return rows, pairs.det[keep], cost[keep], n_cameras

    def _view_choices(self, cylinders: Cylinders, candidates: _Passes, chi2: float, count: int, within: float,
                      memo: RankingMemo | None) -> list[Choice]:  # fmt: skip
        """``branch``'s ranked matchings of views to slots; a choice's ``track`` repeats a track
        once for each view it takes. Costed as ``_choices`` is, but a slot left over is free."""
        rows, cols, cost, n_cameras = self._view_pairs(cylinders, candidates, chi2)
        leftover = leftover_cost(chi2)
        n_views = int((candidates.strong | candidates.weak).sum())
        ranked = ranked_matchings(rows, cols, cost, len(self._tracks) * n_cameras, len(cylinders), leftover, count,
                                  within, memo)  # fmt: skip
        best = ranked[0]
        taken_by = np.full(len(self._tracks) * n_cameras, -1, dtype=np.int64)
        taken_by[best.rows] = best.cols
        paid = float(cost[taken_by[rows] == cols].sum())
        base = paid + leftover * (n_views - 2 * len(best.rows))
        return [Choice(m.rows // n_cameras, m.cols, base + m.extra) for m in ranked]

    def _choices(self, n_detections: int, candidates: _Passes, chi2: float, count: int, within: float,
                 memo: RankingMemo | None) -> list[Choice]:  # fmt: skip
        """``branch``'s ranked matchings, for tracks already moved to the update's time."""
        strong, pairs = candidates.strong, candidates.pairs
        if pairs.d2 is None or pairs.log_det is None or pairs.height is None:
            raise ValueError("ranked choices need the pairs' likelihoods (the uncertainty gate)")
        confirmed = self._tracks.confirmed
        leftover = 0.5 * (chi2 + 4.0 * math.log(self.config.measurement_std_m))
        cost = pairs.d2 + pairs.log_det + pairs.height
        allowed = confirmed[pairs.track] & strong[pairs.det] & (pairs.dist <= self.config.gate_m)
        allowed &= cost < 2.0 * leftover
        track, det, cost = pairs.track[allowed], pairs.det[allowed], cost[allowed]
        ranked = ranked_matchings(track, det, cost, len(confirmed), n_detections, leftover, count, within, memo)
        best = ranked[0]
        taken_by = np.full(len(confirmed), -1, dtype=np.int64)
        taken_by[best.rows] = best.cols
        paid = float(cost[taken_by[track] == det].sum())
        base = paid + leftover * (int(confirmed.sum()) + int(strong.sum()) - 2 * len(best.rows))
        return [Choice(m.rows, m.cols, base + m.extra) for m in ranked]

    def _update(self, cylinders: Cylinders, time_s: float, dt: float, candidates: _Passes, choice: Choice | None) -> None:
        """``update`` after the prediction: the association passes (the first one as ``choice``
        has it, where given), the filters' correction, confirmations, retirements and births."""
        if self.config.track_views:
            self._update_views(cylinders, time_s, dt, candidates, choice)
            return
        cfg = self.config
        tracks = self._tracks
        strong, weak, near, pairs = candidates.strong, candidates.weak, candidates.near, candidates.pairs
        taken = np.zeros(len(cylinders), dtype=bool)
        passes = [
            (pairs, tracks.confirmed, strong, cfg.gate_m),
            (pairs, ~tracks.confirmed, strong, cfg.gate_m),
            (pairs, tracks.confirmed, weak, cfg.weak_gate_m),
        ]
        if cfg.gate_chi2 is not None and cfg.lost_speed_mps is not None:
            passes.append((near, tracks.confirmed, strong, min(cfg.gate_m, cfg.lost_speed_mps * dt)))
        for n, (pass_pairs, track_ok, det_ok, gate) in enumerate(passes):
            if n == 0 and choice is not None:
                tracks.detection[choice.track] = choice.detection
            else:
                self._associate(pass_pairs, track_ok & (tracks.detection < 0), det_ok & ~taken, gate)
            taken[tracks.detection[tracks.detection >= 0]] = True

        self._correct(cylinders)
        self._confirm()
        self._retire()
        self._birth(cylinders, strong & ~taken, time_s)

    def _update_views(self, cylinders: Cylinders, time_s: float, dt: float, candidates: _Passes,
                      choice: Choice | None) -> None:  # fmt: skip
        """``_update`` with ``track_views``: views to slots (as ``choice`` has it, or the best
        matching), then a confirmed track that took none may take a strong view left over within
        ``lost_speed_mps`` (as in ``_update``), each track is corrected with its views fused, and
        the views still left over may start tracks."""
        cfg = self.config
        owner = np.full(len(cylinders), -1, dtype=np.int64)
        if choice is not None:
            owner[choice.detection] = choice.track
        else:
            chi2 = cfg.gate_chi2
            assert chi2 is not None  # TrackerConfig requires it with track_views
            rows, cols, cost, n_cameras = self._view_pairs(cylinders, candidates, chi2)
            r, c = assign_edges(rows, cols, cost, len(self._tracks) * n_cameras, len(cylinders), leftover_cost(chi2))
            owner[c] = r // n_cameras
        if cfg.lost_speed_mps is not None and len(self._tracks):
            tracks = self._tracks
            unseen = np.ones(len(tracks), dtype=bool)
            unseen[owner[owner >= 0]] = False
            gate = min(cfg.gate_m, cfg.lost_speed_mps * dt)
            self._associate(candidates.near, tracks.confirmed & unseen, candidates.strong & (owner < 0), gate)
            found = np.flatnonzero(tracks.detection >= 0)
            owner[tracks.detection[found]] = found
        self._correct_views(cylinders, owner)
        keys = np.where(owner >= 0, self._tracks.key[np.maximum(owner, 0)], -1) if len(self._tracks) else owner
        self._view_keys = keys
        self._confirm()
        self._retire()
        self._birth_from_views(cylinders, candidates.strong & (owner < 0), time_s)

    def _correct_views(self, cylinders: Cylinders, owner: IntArray) -> None:
        """Correct each track with the views it took (``owner``: each view's track row, or −1),
        fused by their information (``bevflow.tracking.views.fuse_views``)."""
        tracks, weight = self._tracks, self.config.shape_smoothing
        det = np.flatnonzero(owner >= 0)
        hit = np.zeros(len(tracks), dtype=bool)
        if len(det):
            covariance = self._covariance_or_fixed(cylinders, det)
            rows, xy, fused_covariance = fuse_views(cylinders.xy[det], covariance, owner[det], len(tracks))
            tracks.state[rows], tracks.covariance[rows] = self._kalman.update(
                tracks.state[rows], tracks.covariance[rows], xy, measurement_covariance=fused_covariance
            )
            views = np.bincount(owner[det], minlength=len(tracks))[rows]
            for column, values in ((tracks.height, cylinders.height[det]), (tracks.radius, cylinders.radius[det])):
                mean = np.bincount(owner[det], weights=values, minlength=len(tracks))[rows] / views
                column[rows] = smooth(column[rows], mean, weight)
            tracks.stature, tracks.stature_variance = fused_stature(
                tracks.stature, tracks.stature_variance, cylinders.stature[det], owner[det]
            )
            first = np.full(len(tracks), len(cylinders), dtype=np.int64)
            np.minimum.at(first, owner[det], det)
            tracks.detection[rows] = first[rows]
            hit[rows] = True
        tracks.hits[hit] += 1
        tracks.misses[hit] = 0
        tracks.misses[~hit] += 1

    def _birth_from_views(self, cylinders: Cylinders, leftover: BoolArray, time_s: float) -> None:
        """Start tentative tracks where the strong views no track took, fused among themselves,
        place someone outside the gate (``gate_chi2``) of every track that took a view now: one
        inside is taken for a second box of that track's person. A track that took no view, whose
        person may be the one placed, holds no birth back."""
        if not leftover.any() or self._fuse is None:
            return
        fused = self._fuse(cylinders[leftover])
        placed = np.isfinite(fused.xy).all(axis=1) & (fused.score > 0)
        seen = self._tracks.misses == 0
        if seen.any() and placed.any():
            placed &= ~self._explained(fused, seen).any(axis=1)
        before = len(self._tracks)
        self._birth(fused, placed, time_s)
        self._tracks.detection[before:] = -1  # born from fused views, not from one input row

    def _explained(self, people: Cylinders, rows: BoolArray) -> BoolArray:
        """(people, tracks ``rows``): whether each person lies within the gate of each track's
        feet, under the sum of both covariances (a person without one: ``measurement_std_m``)."""
        nominal = self.config.measurement_std_m**2 * np.eye(2)
        own = np.broadcast_to(nominal, (len(people), 2, 2)) if people.covariance is None else people.covariance
        known: BoolArray = np.all(np.isfinite(own), axis=(1, 2))
        own = np.where(known[:, None, None], own, nominal)
        joint = own[:, None] + self._tracks.covariance[None, rows, :2, :2]
        d2 = mahalanobis2(people.xy[:, None, :] - self._tracks.state[None, rows, :2], joint)
        chi2 = self.config.gate_chi2
        explained: BoolArray = d2 < (chi2 if chi2 is not None else 0.0)
        return explained

    def report(self, sightings: Cylinders | None = None) -> TrackTable:
        """The confirmed tracks the last update reports (see ``TrackerConfig.report_max_misses``;
        ``sightings`` as for ``update``): what ``update`` returns."""
        cfg = self.config
        report = self._tracks.confirmed & (self._tracks.misses <= cfg.report_max_misses)
        if cfg.coast_needs_sighting:
            coasting = np.flatnonzero(report & (self._tracks.misses > 0))
            report[coasting] = self._sighted(coasting, sightings)
        return self._tracks.select(report).table(self._time_s if self._time_s is not None else 0.0)

    def _predict(self, time_s: float) -> float:
        """Move the clock and every track to ``time_s``; the seconds since the last update."""
        dt = self._advance_clock(time_s)
        tracks = self._tracks
        if len(tracks):
            tracks.state, tracks.covariance = self._kalman.predict(tracks.state, tracks.covariance, dt)
            tracks.stature_variance = tracks.stature_variance + STATURE_DRIFT_M**2 * dt
        tracks.detection = np.full(len(tracks), -1, dtype=np.int64)
        return dt

    def _candidates(self, cylinders: Cylinders) -> _Passes:
        """What every association pass of an update chooses from, found once for all of them."""
        cfg = self.config
        usable = np.isfinite(cylinders.xy).all(axis=1) & (cylinders.score >= cfg.min_score)
        strong = usable & (cylinders.score >= cfg.weak_score)
        det_xy = np.where(usable[:, None], cylinders.xy, np.nan)
        near = _Candidates(*gated_pairs(self._tracks.state[:, :2], det_xy, max(cfg.gate_m, cfg.weak_gate_m)))
        pairs = near if cfg.gate_chi2 is None else self._within_innovation(near, cylinders, cfg.gate_chi2)
        return _Passes(strong, usable & ~strong, near, pairs)

    def _sighted(self, rows: IntArray, sightings: Cylinders | None) -> BoolArray:
        """Which tracks ``rows`` have a sighting within the gate of their predicted feet."""
        if sightings is None or not len(sightings) or not len(rows):
            return np.zeros(len(rows), dtype=bool)
        if sightings.covariance is None:
            raise ValueError("sightings must carry their covariance (bevflow.fusion gives them one)")
        tracks = self._tracks
        offset = sightings.xy[None, :, :] - tracks.state[rows, None, :2]  # (tracks, sightings, 2)
        joint = tracks.covariance[rows, None, :2, :2] + sightings.covariance[None]
        d2 = mahalanobis2(offset, joint)
        sighted: BoolArray = np.asarray((d2 < self.config.sighting_gate_chi2).any(axis=1))
        return sighted

    def _advance_clock(self, time_s: float) -> float:
        time_s = float(time_s)
        if not math.isfinite(time_s):
            raise ValueError(f"time_s must be a finite number of seconds, got {time_s}")
        if self._time_s is not None and time_s < self._time_s:
            raise ValueError(
                f"time went backwards: update at t={time_s:.6f} s after one at t={self._time_s:.6f} s; "
                "feed the tracker in capture-time order"
            )
        dt = 0.0 if self._time_s is None else time_s - self._time_s
        self._time_s = time_s
        return dt

    def _within_innovation(self, pairs: _Candidates, cylinders: Cylinders, chi2: float) -> _Candidates:
        """The ``pairs`` whose detection lies within ``chi2`` of the track's predicted feet, under
        the sum S of the track's position covariance and the detection's (``gate_chi2``), with
        their Mahalanobis distance² and ln |S| to cost them by."""
        track, det = pairs.track, pairs.det
        tracks = self._tracks
        joint = tracks.covariance[track, :2, :2] + self._covariance_or_fixed(cylinders, det)
        offset = cylinders.xy[det] - tracks.state[track, :2]
        size = determinant(joint)
        d2 = mahalanobis2(offset, joint, size)
        log_det = np.log(size)
        keep = d2 < chi2
        track, det = track[keep], det[keep]
        height = stature_cost(cylinders.stature[det], tracks.stature[track], tracks.stature_variance[track])
        return _Candidates(track, det, pairs.dist[keep], d2[keep], log_det[keep], chi2, height)

    def _associate(self, pairs: _Candidates, track_ok: BoolArray, det_ok: BoolArray, gate: float) -> None:
        """Match candidate tracks to candidate detections among ``pairs`` within ``gate`` (feet
        distance); writes ``detection`` of the matched tracks."""
        allowed = track_ok[pairs.track] & det_ok[pairs.det] & (pairs.dist <= gate)
        if not allowed.any():
            return
        cost, worst = pairs.cost(allowed, gate)
        # A track or detection left over costs the worst a gated pair could: any pair is worth making.
        r, c = assign_edges(
            pairs.track[allowed], pairs.det[allowed], cost, len(track_ok), len(det_ok), unmatched_cost=worst
        )
        self._tracks.detection[r] = c

    def _correct(self, cylinders: Cylinders) -> None:
        tracks, weight = self._tracks, self.config.shape_smoothing
        hit = tracks.detection >= 0
        det = tracks.detection[hit]
        if len(det):
            tracks.state[hit], tracks.covariance[hit] = self._kalman.update(
                tracks.state[hit], tracks.covariance[hit], cylinders.xy[det],
                measurement_covariance=self._measurement_covariance(cylinders, det),
            )
            tracks.height[hit] = smooth(tracks.height[hit], cylinders.height[det], weight)
            tracks.radius[hit] = smooth(tracks.radius[hit], cylinders.radius[det], weight)
            tracks.stature, tracks.stature_variance = fused_stature(
                tracks.stature, tracks.stature_variance, cylinders.stature[det], np.flatnonzero(hit)
            )
        tracks.hits[hit] += 1
        tracks.misses[hit] = 0
        tracks.misses[~hit] += 1

    def _covariance_or_fixed(self, cylinders: Cylinders, det: IntArray) -> FloatArray:
        """``_measurement_covariance``, or the filter's fixed ``measurement_std_m`` where it gives none."""
        measurement = self._measurement_covariance(cylinders, det)
        if measurement is None:
            return np.broadcast_to(self.config.measurement_std_m**2 * np.eye(2), (len(det), 2, 2))
        return measurement

    def _measurement_covariance(self, cylinders: Cylinders, det: IntArray) -> FloatArray | None:
        """Each detection's own feet covariance, where ``measurement_from_covariance`` asks for
        it and fusion gave one; None: the filter's fixed ``measurement_std_m``."""
        if not self.config.measurement_from_covariance or cylinders.covariance is None:
            return None
        covariance = cylinders.covariance[det]
        fixed = self.config.measurement_std_m**2 * np.eye(2)
        known: NDArray[np.bool_] = np.all(np.isfinite(covariance), axis=(1, 2))
        return np.where(known[:, None, None], covariance, fixed)

    def _confirm(self) -> None:
        tracks = self._tracks
        new = ~tracks.confirmed & (tracks.hits >= self.config.activate_hits)
        # Ids go in order of birth, so they are reproducible for a given input.
        order = np.flatnonzero(new)
        tracks.id[order] = [self._numbering.id_of(key) for key in tracks.key[order].tolist()]
        tracks.confirmed[new] = True

    def _retire(self) -> None:
        tracks, cfg = self._tracks, self.config
        limit = np.where(tracks.confirmed, cfg.max_misses, cfg.tentative_max_misses)
        self._tracks = tracks.select(tracks.misses < limit)

    def _birth(self, cylinders: Cylinders, unmatched: BoolArray, time_s: float) -> None:
        det = np.flatnonzero(unmatched)
        if len(det) == 0:
            return
        state, covariance = self._kalman.initiate(cylinders.xy[det])
        n = len(det)
        hits = np.ones(n, np.int64)
        if self.config.confirm_multi_view:
            hits[cylinders.camera[det] == -1] = self.config.activate_hits
        born = _Tracks(
            id=np.full(n, -1, np.int64), state=state, covariance=covariance, height=cylinders.height[det].copy(),
            radius=cylinders.radius[det].copy(), hits=hits, misses=np.zeros(n, np.int64),
            born_s=np.full(n, time_s), detection=det.astype(np.int64), confirmed=np.zeros(n, bool),
            key=self._numbering.next_key + np.arange(n, dtype=np.int64),
            stature=np.full(n, np.nan), stature_variance=np.full(n, np.inf),
        )  # fmt: skip
        self._numbering.next_key += n
        self._tracks = self._tracks.append(born)
        self._confirm()


@dataclass(frozen=True, eq=False)
class Branches:
    """What ``Tracker.branch`` found: the ``choices`` (cheapest first) of one tracker moved to the
    update's time, each made into a tracker only when asked (``child``)."""

    choices: list[Choice]
    moved: Tracker
    cylinders: Cylinders
    time_s: float
    dt: float
    candidates: _Passes

    def child(self, choice: Choice) -> Tracker:
        """A copy of the moved tracker updated with ``choice`` (one of ``choices``)."""
        child = self.moved.copy()
        child._update(self.cylinders, self.time_s, self.dt, self.candidates, choice)
        return child
