"""Merging the cylinders that several overlapping cameras see of one person (the paper's section 3.6).

The paper merges cylinders of different cameras whose feet are closer than 0.45 m. That rule was
made for ceiling cameras looking straight down, where every estimate is about equally good in
every direction. A camera that looks sideways is not: a box edge a few pixels off moves the feet
tenths of a metre *along the line of sight* of a person far away, and hardly at all across it.
So each cylinder carries how uncertain its feet are, and two cylinders are one person when their
feet agree *within that uncertainty*.

**Position covariance** (``position_covariance``). A fit follows its box's anchor pixel (the box
point nearest the nadir, ``bevflow.cylinder``). The box is taken to be off by ``box_fraction`` of
its size in each image direction (σ), the box being the image of the fitted cylinder, and that
pixel error is carried to the floor through the camera's local Jacobian (the inverse of the 2 × 2
derivative of ``project`` at the feet): an ellipse, long along the line of sight where the ray is
shallow. ``floor_m`` (σ, every direction) adds what the fit gets wrong even from a perfect box. Feet
rebuilt from the head (``occluded``) rest on an assumed height: ``head_height_m`` of height error
moves them along the line of sight by that times the head ray's run per metre of drop, and the
pixel error is carried through the head's plane instead of the floor's. On WILDTRACK with 2 % box
jitter, ``box_fraction`` = the jitter and ``floor_m`` = 0.05 m bring the cylinder fits' normalised
squared errors near χ²(2) (median 1.7 against 1.4, 99th percentile 11.8 against 9.2). The defaults
(0.03, 0.1 m) are wider (median 0.6, 99th percentile 3.8); end to end they merged best there (MODA
0.86 against 0.82), and under a ceiling fisheye 3.3 m up they gate at 0.45–0.55 m, about the
paper's distance.

A cylinder may carry its covariance (``Cylinders.covariance``): the projector computes it once
per detection with ``with_position_covariance``, the same function of the same inputs, so the
central tick does not project every cylinder again; fusion computes only the rows that lack one.

**Gate.** Two cylinders of different cameras may be one person when their feet are closer than
``distance_m`` (the paper's rule, kept so overhead cameras behave as in the paper) *or* their
Mahalanobis distance under the sum of the two covariances is below ``gate_chi2`` (9.21: 99 % of
χ²(2)) and they are closer than ``max_gate_m`` (no camera places a person well enough to be merged
from farther). Two cylinders of the same camera never are: a detector that reports two boxes has
seen two people.

**Groups.** Chains are cut, not followed: if A ~ B and B ~ C but not A ~ C, A and C cannot be one
person, so a group must be a *clique*, every pair of its members linked (complete linkage). Groups
are grown greedily from the surest pair up (each pair ranked by how deep inside its gate it lies:
the smaller of d² / ``gate_chi2`` and (distance / ``distance_m``)²), so in the chain above B joins
whichever of A and C agrees with it better. The common case, every candidate group already a clique
of distinct cameras, is settled in one vectorised pass; only tangled groups go through the greedy
loop. Candidate pairs come from a k-d tree queried at the largest gate any pair can have (capped at
``max_gate_m``), never from all pairs, so the cost follows the number of cylinders.

**Fused position.** The information-weighted mean of the members' feet (each weighted by its
inverse covariance), so a side view's estimate counts across its line of sight and hardly along
it. Height and radius are averaged with weights 1 / √det(covariance) (the inverse area of each
ellipse). The score (the box's overlap with the model) does not weigh the position: it is not a
distance error, and leaving it out measured slightly better. ``score`` is the best member's;
``occluded`` holds only when every view was occluded.

**Weak views.** A cylinder with score ≤ 0 is *weak*: ``bevflow.cylinder`` gives that to a box whose
lower body looks hidden where its feet cannot be rebuilt from the head (a side-view camera), so its
floor position may be metres off. A weak view still joins a group (it confirms another camera's view
of the person) but does not move the fused position, and a group of weak views only is not a person
(unless they cross, below, or a track vouches for them, "Tracks as priors"): its inputs get
assignment −1. Those views are kept as *sightings*: a camera saw part of someone there and could not
place them, which tells the tracker that a person it misses may still be standing behind someone
(``bevflow.tracking.tracker``, ``coast_needs_sighting``). A sighting's covariance is its fit's plus
``weak_along_m`` along its camera's line of sight: its bearing is as good as any view's, its range
is not.

**Cut views that cross.** A cut box places its person too far along its own camera's line of sight,
so two cameras looking the same way can agree on a point where nobody stands, but two whose lines of
sight cross at ``crossing_deg`` (45°) or more agree only near where the person stands. A group of
weak views only, of two or more cameras, every two within ``distance_m`` of each other, two of whose
lines of sight cross at that angle, is therefore a person, placed by their mean (weighted as any
group's), with score ``CROSSED_CUT_VIEWS_SCORE``: one the tracker may start a track from. In a crowd
seen from the side many boxes are cut (CMC2: four cameras 2.15 m up around a small room, up to 10
people): there 211 of the 214 people so placed stood within 0.5 m of someone (``docs/RESULTS.md``,
CMC2). Where any two cameras' weak views agreeing under the gate made a person, none of the 77 so
made on WILDTRACK's replayed boxes (2 % jitter) stood within 0.5 m of anyone, and 53 of them were
seen from less than 15° apart; with both rules 2 are left there, and the per-frame evaluation gains
one false positive in 200 frames. Off with ``noise=None`` (the paper's rule).

**Hidden views the occlusion test missed.** On a shallow view a box cut by a nearer person can
escape both occlusion tests (``bevflow.cylinder``); its fit is then a strong single view placed
metres too far along its camera's line of sight, a second estimate of a person the other
cameras place well (on WILDTRACK 71 of the per-frame false positives). So a person seen by one
camera only, on a ray shallower than ``hidden_view_slope`` (horizontal run per metre of the
camera's height; 4, as ``bevflow.cylinder`` allows a head rebuild), is folded into a person of
two or more views when that person stands nearer the camera on the same line of sight (within
``gate_chi2`` of it under their covariances, the single view's widened by ``weak_along_m`` along
its line of sight, as a sighting's) and that camera is not among their views: had the camera
seen them whole it would have boxed them. The folded view counts in ``n_views`` and does not
move the person, as a weak view. On WILDTRACK (2 % jitter, 10 % drops, seed 0) the per-frame
false positives fall from 216 to 158 and the misses rise from 406 to 412 (MODA 0.870 → 0.881).
Ceiling cameras look down steeper than that within their monitored radius, so the paper's case
is untouched.

**Tracks as priors.** Fusion on its own judges each pair of views by their feet alone; on real
side views (CMC2: four cameras 2.15 m up in a small room) one person's views scatter by 0.2–0.5 m,
past the gate, so a person splits into two estimates. ``priors``, the tracker's predicted feet
(``Tracker.predicted``, with their covariance), join them: each camera's views are assigned, one
to one, to the priors within ``gate_chi2`` of them (Mahalanobis under the sum of both
covariances; as many pairs as possible, at the least total d²), and after the grouping above,
groups whose views went to one prior become one person where their cameras differ (one camera
never boxes a person twice).
Priors only join, never split: a stale or duplicate track that takes one camera's view of a
person must not keep that view from the person's other views (tried: on the detector suite's
queue, seq 5 with both cameras, it kept duplicates alive, MOTA 0.941 → 0.894). A group of weak
views only is a person where one of its views went to a prior: the track says someone is there
(the tracker continues only confirmed tracks with weak detections).

``noise=None`` is the paper's fusion: the 0.45 m rule alone, and the mean weighted by score /
range² (range: camera centre to feet), a monocular fit's error growing with range.

>>> from bevflow.camera import FisheyeCamera
>>> cams = [FisheyeCamera.looking_down((x, 0.0, 3.3), (512, 512)) for x in (0.0, 4.0)]
>>> seen = Cylinders(xy=[[2.0, 0.0], [2.1, 0.0]], camera=[0, 1])
>>> fuse_cylinders(seen, cams).n_views.tolist()
[2]
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from bevflow import matrix2
from bevflow.camera import Camera
from bevflow.detections import Cylinders
from bevflow.metrics.matching import assign_edges, gated_pairs

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_PROBE_M = 0.01  # floor step of the finite-difference Jacobian of ``project``
CROSSED_CUT_VIEWS_SCORE = 0.5
"""The score of a person placed by cut views that cross (module docstring): a middling fit's, enough
for the tracker to start a track from them (``TrackerConfig.weak_score``, 0.3, is its bar)."""
_SQUARE = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])


@dataclass(frozen=True)
class PositionNoise:
    """How uncertain one camera's feet estimate is (σ values; see the module docstring)."""

    box_fraction: float = 0.03  # box error in each image direction, as a fraction of the box size
    floor_m: float = 0.1  # the fit's own error on the floor, every direction
    head_height_m: float = 0.1  # people's height error, for feet rebuilt from the head
    weak_along_m: float = 3.0  # a weak view's feet error along its line of sight (sightings)

    def __post_init__(self) -> None:
        if not (self.box_fraction >= 0 and self.floor_m > 0 and self.head_height_m >= 0 and self.weak_along_m >= 0):
            raise ValueError(
                f"PositionNoise needs box_fraction >= 0, floor_m > 0, head_height_m >= 0, weak_along_m >= 0; got {self}"
            )


@dataclass(frozen=True)
class Fusion:
    """``fused``: one row per person, ``camera`` the single camera that saw them or −1 when fused
    from several. ``assignment`` (len(input),): the fused row of each input cylinder, −1 for inputs
    dropped (non-finite feet, or in a group of weak views only that is no one: module docstring,
    "Weak views"). ``n_views`` (len(fused),): how many cameras saw each person. ``sightings``: the
    weak views in no person's group, each with its bearing covariance (module docstring, "Weak
    views")."""

    fused: Cylinders
    assignment: IntArray
    n_views: IntArray
    sightings: Cylinders = field(default_factory=Cylinders.empty)


def fuse_cylinders(
    cylinders: Cylinders,
    cameras: Sequence[Camera],
    distance_m: float = 0.45,
    *,
    noise: PositionNoise | None = PositionNoise(),
    gate_chi2: float = 9.21,
    max_gate_m: float = 2.0,
    hidden_view_slope: float = 4.0,
    crossing_deg: float = 45.0,
    priors: Cylinders | None = None,
) -> Fusion:
    """Merge the cylinders of different cameras that are one person: feet closer than
    ``distance_m``, or (unless ``noise`` is None) within ``gate_chi2`` of each other given their
    position covariances and closer than ``max_gate_m``. ``cylinders.camera`` indexes ``cameras``.
    With ``noise``, rows with a finite ``cylinders.covariance`` use it and ``noise`` gives the
    others theirs; the paper's rule (``noise=None``) uses no covariance. ``hidden_view_slope``: see
    "Hidden views the occlusion test missed" (``math.inf`` folds none; the paper's rule folds none).
    ``crossing_deg``: see "Cut views that cross" (``math.inf`` places none; the paper's rule places
    none). ``priors``: people expected this tick, feet and covariance (module docstring, "Tracks as
    priors"); used only with ``noise``."""
    if not (distance_m > 0 and gate_chi2 > 0 and max_gate_m > 0 and hidden_view_slope > 0 and crossing_deg > 0):
        raise ValueError(
            "distance_m, gate_chi2, max_gate_m, hidden_view_slope and crossing_deg must be > 0, got "
            f"{distance_m}, {gate_chi2}, {max_gate_m}, {hidden_view_slope}, {crossing_deg}"
        )
    _check_cameras(cylinders, cameras)
    keep = np.flatnonzero(np.isfinite(cylinders.xy).all(axis=1))
    assignment = np.full(len(cylinders), -1, dtype=np.int64)
    rows = cylinders[keep]
    on_prior = np.zeros(len(rows), dtype=bool)
    if noise is None:
        info = _range_information(rows, cameras)
        labels = _group(rows.xy, rows.camera, None, distance_m, gate_chi2, max_gate_m)
    else:
        covariance = _carried_or_computed_covariance(rows, cameras, noise)
        info = matrix2.inverse(covariance)
        if priors is not None and len(priors):
            labels, on_prior = _group_with_priors(rows, covariance, priors, distance_m, gate_chi2, max_gate_m)
        else:
            labels = _group(rows.xy, rows.camera, covariance, distance_m, gate_chi2, max_gate_m)
    n_strong = np.bincount(labels, weights=rows.score > 0)
    expected = np.bincount(labels, weights=on_prior, minlength=len(n_strong)) > 0
    crossed = np.zeros(len(n_strong), dtype=bool)
    if noise is not None and math.isfinite(crossing_deg):
        crossed = _cut_views_crossing(rows, labels, n_strong == 0, cameras, distance_m, crossing_deg)
    # A group of weak views only is placed by them where a prior vouches for someone there, or
    # where cut views of different cameras cross.
    vouched = expected | crossed
    placed_by_weak = (n_strong == 0) & vouched
    strong = (rows.score > 0) | placed_by_weak[labels]
    real = ((n_strong > 0) | vouched)[labels]
    sightings = _sightings(rows[~real], cameras, noise or PositionNoise())
    if not real.any():
        return Fusion(Cylinders.empty(), assignment, np.zeros(0, dtype=np.int64), sightings)
    # Number the people in the order their first cylinder arrived.
    _, first, inverse = np.unique(labels[real], return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    person = rank[inverse]
    assignment[keep[real]] = person
    weight = np.where(strong[real], 1.0, 0.0)[:, None, None] * info[real]
    fused, n_views = _merge(rows[real], person, len(order), weight, with_covariance=noise is not None)
    if crossed.any():
        by_crossing = np.bincount(person, weights=crossed[labels[real]], minlength=len(fused)) > 0
        fused = replace(fused, score=np.where(by_crossing, CROSSED_CUT_VIEWS_SCORE, fused.score))
    if noise is not None and math.isfinite(hidden_view_slope):
        seen_by = np.zeros((len(fused), len(cameras)), dtype=bool)
        seen_by[person, rows.camera[real]] = True
        into = _hidden_behind(fused, n_views, seen_by, cameras, noise.weak_along_m, gate_chi2, hidden_view_slope)
        fused, n_views, assignment = _fold(fused, n_views, assignment, into)
    return Fusion(fused, assignment, n_views, sightings)


def _cut_views_crossing(
    rows: Cylinders, labels: IntArray, weak_only: NDArray[np.bool_], cameras: Sequence[Camera],
    distance_m: float, crossing_deg: float,
) -> NDArray[np.bool_]:
    """For each group: weak views only, of two or more cameras, every two within ``distance_m``,
    and two of them seen along lines of sight at least ``crossing_deg`` apart (module docstring,
    "Cut views that cross")."""
    crossed = np.zeros(len(weak_only), dtype=bool)
    sizes = np.bincount(labels, minlength=len(weak_only))
    candidates = np.flatnonzero(weak_only & (sizes >= 2))  # a group holds one view per camera
    if not len(candidates):
        return crossed
    # The candidates' rows sorted by group; a group's every pair is (i, i + k) for some offset k
    # below its size, so the pairs of all groups are taken together, offset by offset.
    member = np.flatnonzero(np.isin(labels, candidates))
    member = member[np.argsort(labels[member], kind="stable")]
    group, xy = labels[member], rows.xy[member]
    sight = xy - _camera_centres(cameras, rows.camera[member])[:, :2]
    sight /= np.maximum(np.linalg.norm(sight, axis=1, keepdims=True), 1e-12)
    widest_cosine = math.cos(math.radians(min(crossing_deg, 180.0)))
    apart = np.zeros(len(weak_only), dtype=bool)  # some two views farther than distance_m
    across = np.zeros(len(weak_only), dtype=bool)  # some two lines of sight crossing widely enough
    for k in range(1, int(sizes[candidates].max())):
        i = np.flatnonzero(group[:-k] == group[k:])
        j = i + k
        apart[group[i[np.linalg.norm(xy[i] - xy[j], axis=1) >= distance_m]]] = True
        across[group[i[np.einsum("ij,ij->i", sight[i], sight[j]) <= widest_cosine]]] = True
    crossed[candidates] = across[candidates] & ~apart[candidates]
    return crossed


def _hidden_behind(
    fused: Cylinders, n_views: IntArray, seen_by: NDArray[np.bool_], cameras: Sequence[Camera],
    along_m: float, gate_chi2: float, min_slope: float,
) -> IntArray:
    """For each fused person, the person of several views they are a missed cut view of (module
    docstring, "Hidden views the occlusion test missed"), or −1."""
    into = np.full(len(fused), -1, dtype=np.int64)
    covariance_of = fused.covariance
    if covariance_of is None:  # the test weighs distances by the fused feet's covariances
        return into
    several = np.flatnonzero(n_views >= 2)
    singles = np.flatnonzero((n_views == 1) & (fused.score > 0))
    if not len(several) or not len(singles):
        return into
    centres = _camera_centres(cameras, fused.camera[singles])
    away = fused.xy[singles] - centres[:, :2]
    run = np.linalg.norm(away, axis=1)
    for k in np.flatnonzero(run >= min_slope * centres[:, 2]):
        s, camera, sight = singles[k], fused.camera[singles[k]], away[k] / run[k]
        behind = several[~seen_by[several, camera]]
        along = (fused.xy[behind] - centres[k, :2]) @ sight
        offset = fused.xy[behind] - fused.xy[s]
        covariance = covariance_of[behind] + covariance_of[s] + along_m**2 * np.outer(sight, sight)
        d2 = matrix2.mahalanobis2(offset, covariance)
        hides = (along > 0) & (along < run[k]) & (d2 < gate_chi2)
        if hides.any():
            into[s] = behind[hides][np.argmin(d2[hides])]
    return into


def _fold(fused: Cylinders, n_views: IntArray, assignment: IntArray, into: IntArray) -> tuple[Cylinders, IntArray, IntArray]:
    """Fold each person with ``into`` ≥ 0 into that person: one more view, same position."""
    folded = into >= 0
    if not folded.any():
        return fused, n_views, assignment
    n_views = n_views.copy()
    np.add.at(n_views, into[folded], n_views[folded])
    target = np.where(folded, into, np.arange(len(fused)))
    renumber = np.cumsum(~folded) - 1
    assignment = np.where(assignment >= 0, renumber[target[np.maximum(assignment, 0)]], -1)
    return fused[~folded], n_views[~folded], assignment


def _sightings(weak: Cylinders, cameras: Sequence[Camera], noise: PositionNoise) -> Cylinders:
    """The weak views that placed nobody, with their fit's covariance widened along the line of
    sight by ``noise.weak_along_m``."""
    if not len(weak):
        return replace(weak, covariance=np.zeros((0, 2, 2)))
    covariance = _carried_or_computed_covariance(weak, cameras, noise)
    away = weak.xy - _camera_centres(cameras, weak.camera)[:, :2]
    with np.errstate(invalid="ignore", divide="ignore"):
        along = away / np.linalg.norm(away, axis=1, keepdims=True)
    along = np.where(np.isfinite(along), along, 0.0)  # feet right below the camera: no direction
    covariance = covariance + noise.weak_along_m**2 * along[:, :, None] * along[:, None, :]
    return replace(weak, covariance=covariance)


def position_covariance(
    cylinders: Cylinders, cameras: Sequence[Camera], noise: PositionNoise = PositionNoise()
) -> FloatArray:
    """(N, 2, 2) covariance of each cylinder's feet on the floor, m², from its camera's geometry
    (see the module docstring). Rows whose geometry does not project (feet outside the camera's
    field) get the ``floor_m`` term alone."""
    _check_cameras(cylinders, cameras)
    n = len(cylinders)
    xy, height, occluded = cylinders.xy, cylinders.height, cylinders.occluded
    # Per row, 11 world points: the 8 corners of the cylinder's outer cuboid (its box is their
    # image), then where the anchor's ray is followed (the floor, or the head's plane for rebuilt
    # feet) and two steps along x and y from it (the Jacobian). One projection call per camera.
    ring = xy[:, None] + cylinders.radius[:, None, None] * _SQUARE
    base = np.concatenate([xy, np.where(occluded, height, 0.0)[:, None]], axis=1)
    points = np.concatenate([
        np.concatenate([ring, np.zeros((n, 4, 1))], axis=2),
        np.concatenate([ring, np.repeat(height[:, None, None], 4, axis=1)], axis=2),
        np.stack([base, base + [_PROBE_M, 0.0, 0.0], base + [0.0, _PROBE_M, 0.0]], axis=1),
    ], axis=1)
    uv = np.full((n, 11, 2), np.nan)
    finite = np.flatnonzero(np.isfinite(xy).all(axis=1))
    by_camera = finite[np.argsort(cylinders.camera[finite], kind="stable")]
    starts = np.flatnonzero(np.diff(cylinders.camera[by_camera], prepend=-1))
    for rows in np.split(by_camera, starts[1:]):  # one run of rows per camera
        if len(rows):
            camera = cameras[int(cylinders.camera[rows[0]])]
            uv[rows] = camera.project(points[rows].reshape(-1, 3)).reshape(-1, 11, 2)

    pixel_sigma = noise.box_fraction * (uv[:, :8].max(axis=1) - uv[:, :8].min(axis=1))
    jacobian = np.stack([uv[:, 9] - uv[:, 8], uv[:, 10] - uv[:, 8]], axis=2) / _PROBE_M  # d(u, v) / d(x, y)
    to_floor = matrix2.inverse(jacobian)
    pixel_covariance = np.zeros((n, 2, 2))
    pixel_covariance[:, 0, 0], pixel_covariance[:, 1, 1] = pixel_sigma[:, 0] ** 2, pixel_sigma[:, 1] ** 2
    covariance = to_floor @ pixel_covariance @ to_floor.transpose(0, 2, 1)
    covariance[~np.isfinite(covariance).all(axis=(1, 2))] = 0.0
    covariance[:, 0, 0] += noise.floor_m**2
    covariance[:, 1, 1] += noise.floor_m**2
    if occluded.any():
        covariance += _head_height_covariance(cylinders, cameras, noise.head_height_m)
    # Exactly symmetric (the products above are only up to rounding), so three numbers carry it.
    return 0.5 * (covariance + covariance.transpose(0, 2, 1))


def with_position_covariance(
    cylinders: Cylinders, cameras: Sequence[Camera], noise: PositionNoise = PositionNoise()
) -> Cylinders:
    """``cylinders`` carrying their ``position_covariance``, for a stage upstream of fusion (the
    projector) to compute it where the camera is at hand, once per detection."""
    return replace(cylinders, covariance=position_covariance(cylinders, cameras, noise))


def with_covariance_where_missing(
    cylinders: Cylinders, cameras: Sequence[Camera], noise: PositionNoise = PositionNoise()
) -> Cylinders:
    """``cylinders`` keeping the covariances they carry, with ``position_covariance`` for the rows
    that carry none: views as the projector sends them, whoever made them."""
    return replace(cylinders, covariance=_carried_or_computed_covariance(cylinders, cameras, noise))


def _carried_or_computed_covariance(rows: Cylinders, cameras: Sequence[Camera], noise: PositionNoise) -> FloatArray:
    """The rows' own covariances where they carry a finite one, ``position_covariance`` elsewhere."""
    if rows.covariance is None:
        return position_covariance(rows, cameras, noise)
    covariance = rows.covariance.copy()
    missing: NDArray[np.bool_] = ~np.all(np.isfinite(covariance), axis=(1, 2))
    if missing.any():
        covariance[missing] = position_covariance(rows[missing], cameras, noise)
    return covariance


def _head_height_covariance(cylinders: Cylinders, cameras: Sequence[Camera], head_height_m: float) -> FloatArray:
    """Along the line of sight, for feet rebuilt from the head: the head ray's run per metre of drop
    times the height error. Zero for other rows."""
    out = np.zeros((len(cylinders), 2, 2))
    centres = _camera_centres(cameras, cylinders.camera)
    away = cylinders.xy - centres[:, :2]
    run = np.linalg.norm(away, axis=1)
    drop = centres[:, 2] - cylinders.height
    with np.errstate(invalid="ignore", divide="ignore"):
        along = away / run[:, None]
        variance = (run / drop * head_height_m) ** 2
        usable = cylinders.occluded & (drop > 0) & (run > 0) & np.isfinite(variance)
    out[usable] = variance[usable, None, None] * along[usable, :, None] * along[usable, None, :]
    return out


def _camera_centres(cameras: Sequence[Camera], index: IntArray) -> FloatArray:
    """(N, 3) centre of the camera of each row (``index`` into ``cameras``)."""
    return np.array([c.center for c in cameras]).reshape(-1, 3)[index]


def _check_cameras(cylinders: Cylinders, cameras: Sequence[Camera]) -> None:
    camera = cylinders.camera
    bad = (camera < 0) | (camera >= len(cameras))
    if bad.any():
        raise ValueError(
            f"cylinder camera index {int(camera[bad][0])} does not name one of the {len(cameras)} cameras "
            "(fuse per-camera cylinders, before any earlier fusion)"
        )


def _largest_eigenvalue(m: FloatArray) -> FloatArray:
    """The larger eigenvalue of each symmetric (N, 2, 2) matrix (its lower triangle read)."""
    a, b, d = m[:, 0, 0], m[:, 1, 0], m[:, 1, 1]
    return 0.5 * (a + d) + np.hypot(0.5 * (a - d), b)


def _range_information(rows: Cylinders, cameras: Sequence[Camera]) -> FloatArray:
    """The paper-rule weights score / range², as isotropic information matrices."""
    centres = _camera_centres(cameras, rows.camera)
    feet = np.concatenate([rows.xy, np.zeros((len(rows), 1))], axis=1)
    range_sq = np.maximum(((feet - centres) ** 2).sum(axis=1), 1e-6)
    covariance: FloatArray = (np.maximum(rows.score, 1e-6) / range_sq)[:, None, None] * np.eye(2)
    return covariance


def _group(
    xy: FloatArray,
    camera: IntArray,
    covariance: FloatArray | None,
    distance_m: float,
    gate_chi2: float,
    max_gate_m: float,
) -> IntArray:
    """A group label per row: cliques of distinct cameras, every pair linked."""
    n = len(xy)
    radius = distance_m
    if covariance is not None and n:
        # d² < χ² needs distance² < χ² · λmax(Σa + Σb) <= χ² · 2 · max λmax. The closed form of
        # a 2 × 2 eigenvalue may round below LAPACK's: a hair of margin keeps every pair that
        # could pass (the search radius only picks candidates; the gate decides).
        largest = float(np.max(_largest_eigenvalue(covariance))) * (1.0 + 1e-9)
        radius = max(distance_m, min(max_gate_m, float(np.sqrt(2.0 * gate_chi2 * largest))))
    pairs = cKDTree(xy).query_pairs(radius, output_type="ndarray") if n else np.zeros((0, 2), dtype=np.int64)
    if len(pairs) == 0:
        return np.arange(n)
    a, b = pairs[:, 0], pairs[:, 1]
    diff = xy[a] - xy[b]
    gap = np.hypot(diff[:, 0], diff[:, 1])
    depth = (gap / distance_m) ** 2  # how deep inside its gate a pair lies: < 1 is inside
    if covariance is not None:
        with np.errstate(invalid="ignore"):
            d2 = matrix2.mahalanobis2(diff, covariance[a] + covariance[b])
        d2 = np.where(np.isfinite(d2) & (gap < max_gate_m), d2, np.inf)
        depth = np.minimum(depth, d2 / gate_chi2)
    usable = (camera[a] != camera[b]) & (depth < 1.0)
    pairs, depth = pairs[usable], depth[usable]
    if len(pairs) == 0:
        return np.arange(n)
    labels = _components(n, pairs[:, 0], pairs[:, 1])
    size = np.bincount(labels, minlength=labels.max() + 1)
    edges = np.bincount(labels[pairs[:, 0]], minlength=len(size))
    # Without same-camera pairs in the graph, a component with every pair linked is a clique of
    # distinct cameras: it is one person as it stands.
    tangled = np.flatnonzero(edges < size * (size - 1) // 2)
    if len(tangled):
        labels = labels.copy()
        in_tangled = np.isin(labels[pairs[:, 0]], tangled)
        _split_greedily(labels, camera, pairs[in_tangled], depth[in_tangled])
    return labels


def _group_with_priors(
    rows: Cylinders, covariance: FloatArray, priors: Cylinders, distance_m: float, gate_chi2: float, max_gate_m: float
) -> tuple[IntArray, NDArray[np.bool_]]:
    """``_group``'s labels, then the groups whose views went to one prior joined where their
    cameras differ (module docstring, "Tracks as priors"); also which rows went to a prior."""
    labels = _group(rows.xy, rows.camera, covariance, distance_m, gate_chi2, max_gate_m)
    prior_of = _views_on_priors(rows, covariance, priors, gate_chi2, max_gate_m)
    on = prior_of >= 0
    prior_group = np.unique(np.stack([prior_of[on], labels[on]], axis=1), axis=0)  # sorted by prior
    split = prior_group[(np.bincount(prior_group[:, 0], minlength=len(priors)) > 1)[prior_group[:, 0]]]
    if not len(split):  # the common case: every prior's views are in one group already
        return labels, on
    starts = np.flatnonzero(np.diff(split[:, 0]))
    return _join(labels, rows.camera, np.split(split[:, 1], starts + 1)), on


def _join(labels: IntArray, camera: IntArray, candidates: list[IntArray]) -> IntArray:
    """``labels`` with each of ``candidates`` (arrays of group labels, in turn) made one group
    where the groups' cameras, as joined so far, are all distinct. Few groups take part (a
    prior's views mostly group as their prior's do), so plain Python over them is cheapest."""
    involved = np.flatnonzero(np.isin(labels, np.concatenate(candidates)))
    members: dict[int, list[int]] = {}
    for row, group in zip(involved.tolist(), labels[involved].tolist(), strict=True):
        members.setdefault(group, []).append(row)
    root = {group: group for group in members}
    joined = {group: list(rows) for group, rows in members.items()}
    cameras = camera.tolist()

    def find(group: int) -> int:
        while root[group] != group:
            group = root[group]
        return group

    for groups in candidates:
        heads = sorted({find(g) for g in groups.tolist()})
        together = [r for head in heads for r in joined[head]]
        if len(heads) > 1 and len({cameras[r] for r in together}) == len(together):
            for head in heads[1:]:
                root[head] = heads[0]
            joined[heads[0]] = together
    out = labels.copy()
    for group, rows in members.items():
        out[rows] = find(group)
    return out


def _views_on_priors(
    rows: Cylinders, covariance: FloatArray, priors: Cylinders, gate_chi2: float, max_gate_m: float
) -> IntArray:
    """The prior each view is assigned to, −1 for none: each camera's views one to one to the
    priors within ``gate_chi2`` (and ``max_gate_m``), as many pairs as possible and among those
    the least total d². Candidates come from k-d trees, so the cost follows the crowd's size."""
    prior_of = np.full(len(rows), -1, dtype=np.int64)
    view, prior, _ = gated_pairs(rows.xy, priors.xy, max_gate_m)
    if not len(view):
        return prior_of
    prior_covariance = priors.covariance if priors.covariance is not None else np.zeros((len(priors), 2, 2))
    offset = rows.xy[view] - priors.xy[prior]
    d2 = matrix2.mahalanobis2(offset, covariance[view] + prior_covariance[prior])
    within = d2 < gate_chi2
    view, prior, d2 = view[within], prior[within], d2[within]
    # One solve for all cameras: a (camera, prior) pair per column keeps each camera's choice its own.
    slots, column = np.unique(rows.camera[view] * len(priors) + prior, return_inverse=True)
    matched_view, matched_slot = assign_edges(view, column, d2, len(rows), len(slots))
    prior_of[matched_view] = slots[matched_slot] % len(priors)
    return prior_of


def _components(n: int, a: IntArray, b: IntArray) -> IntArray:
    """Label each of ``n`` rows with the smallest row of its connected component (edges a–b).
    Components here are the few views of one or two people, so a few rounds of taking the smaller
    label across each edge, with pointer jumping, settle them: far cheaper per tick than building
    a sparse graph for scipy."""
    labels = np.arange(n)
    while True:
        low = np.minimum(labels[a], labels[b])
        np.minimum.at(labels, a, low)
        np.minimum.at(labels, b, low)
        labels = labels[labels]
        if (labels[a] == labels[b]).all():
            return labels


def _split_greedily(labels: IntArray, camera: IntArray, pairs: IntArray, depth: FloatArray) -> None:
    """Relabel the rows of tangled components in place: start from singletons and join groups along
    pairs, surest first, when the cameras are distinct and every cross pair is linked."""
    nodes, local = np.unique(pairs, return_inverse=True)
    local = local.reshape(pairs.shape)
    fresh = labels.max() + 1 + np.arange(len(nodes))
    labels[nodes] = fresh  # every tangled row alone, under a label no clean component uses
    # Plain Python ints as bit sets over the tangled rows (a few hundred per tick): each pair's
    # test is then a couple of integer operations instead of numpy calls or set comparisons.
    k_nodes = range(len(nodes))
    group = list(k_nodes)  # row -> the row its group is named after
    members = [[k] for k in k_nodes]
    mask = [1 << k for k in k_nodes]  # a group's rows
    cameras = [1 << c for c in camera[nodes].tolist()]  # a group's cameras
    common = [0] * len(nodes)  # the rows linked to every row of a group
    ordered = local[np.argsort(depth, kind="stable")].tolist()
    for a, b in ordered:
        common[a] |= 1 << b
        common[b] |= 1 << a
    for a, b in ordered:
        ga, gb = group[a], group[b]
        if ga == gb or cameras[ga] & cameras[gb] or mask[gb] & ~common[ga]:
            continue
        mask[ga] |= mask[gb]
        cameras[ga] |= cameras[gb]
        common[ga] &= common[gb]
        for j in members[gb]:
            group[j] = ga
        members[ga] += members[gb]
    labels[nodes] = fresh[group]


def _merge(
    rows: Cylinders, person: IntArray, n_people: int, info: FloatArray, with_covariance: bool
) -> tuple[Cylinders, IntArray]:
    """One row per person: feet by information-weighted mean (``info``: (N, 2, 2) per row, zero for
    rows that must not move it), height and radius weighted by √det(info), head height
    (``stature``) the mean of the rows that measured one. ``with_covariance``:
    the fused feet carry their covariance, the inverse of the summed information (``info`` is
    then the rows' inverse covariances, not the paper rule's stand-in weights)."""
    n_views = np.bincount(person, minlength=n_people).astype(np.int64)

    def total(values: FloatArray) -> FloatArray:
        """Per person, the sum of ``values`` (N, ...) over their rows (bincount: ufunc.at is slow)."""
        flat = values.reshape(len(values), -1)
        sums = [np.bincount(person, weights=flat[:, k], minlength=n_people) for k in range(flat.shape[1])]
        # Weighted counts are floats; numpy's stubs type every bincount as integers.
        return np.stack(sums, axis=1).astype(np.float64, copy=False).reshape(n_people, *values.shape[1:])

    total_info = total(info)
    moment = total(np.einsum("nij,nj->ni", info, rows.xy))
    covariance = matrix2.inverse(total_info)
    xy = np.einsum("nij,nj->ni", covariance, moment)
    weight = np.sqrt(np.maximum(matrix2.determinant(info), 0.0))
    total_weight = np.bincount(person, weights=weight, minlength=n_people)

    def mean(values: FloatArray) -> FloatArray:
        return np.bincount(person, weights=weight * values, minlength=n_people) / total_weight

    score = np.full(n_people, -np.inf)
    np.maximum.at(score, person, rows.score)
    visible = np.bincount(person, weights=~rows.occluded, minlength=n_people) > 0
    camera = np.full(n_people, -1, dtype=np.int64)
    alone = n_views[person] == 1
    camera[person[alone]] = rows.camera[alone]
    fused = Cylinders(
        xy=xy,
        height=mean(rows.height),
        radius=mean(rows.radius),
        camera=camera,
        score=score,
        occluded=~visible,
        covariance=covariance if with_covariance else None,
        stature=_mean_measured(rows.stature, person, n_people),
    )
    return fused, n_views


def _mean_measured(values: FloatArray, person: IntArray, n_people: int) -> FloatArray:
    """Per person, the mean of their rows' finite ``values``; NaN where none is."""
    measured = np.isfinite(values)
    count = np.bincount(person[measured], minlength=n_people)
    total = np.bincount(person[measured], weights=values[measured], minlength=n_people)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean: FloatArray = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    return mean
