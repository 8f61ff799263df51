"""Ray geometry of the fisheye renderer: where rays from the camera first meet ellipsoids (body
parts, clutter), vertical cylinders (pillars) and boxes (shelves, counters), with the surface
normals for shading. Every function works on K rays at once (numpy arrays, no Python loop over
rays); ``trace_bodies`` tests all the people of a frame in one pass.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from bevflow.sim.bodies import BodyPrimitives
from bevflow.sim.scene import Pillar, Shelf

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def trace_bodies(
    o: FloatArray, d: NDArray[np.float32], products: NDArray[np.float32], bodies: BodyPrimitives, who: IntArray
) -> tuple[NDArray[np.float32], IntArray]:
    """For K rays from o (directions ``d``, their component ``products``) each tested against one
    body (``who``, grouped: a body's rays are consecutive): the distance to that body's nearest
    part (inf: missed) and which part.

    Each part is a quadric (x − c)ᵀ Q (x − c) = 1 with Q = M Mᵀ, M = axes / radii; along the ray
    x = o + t·d that is qa t² + qb t + qc = 0 with qa = dᵀ Q d (six products of d's components),
    qb = 2 dᵀ Q (o − c) and qc = (o − c)ᵀ Q (o − c) − 1 (per part, the same for every ray).
    The K × P stage runs in float32: distances of metres to well under a millimetre (grazing rays
    are the worst) are plenty for pixels of centimetres, and it halves
    the memory traffic that dominates here."""
    k, parts = len(d), bodies.centers.shape[1]
    if not k:
        return np.full(0, np.inf, dtype=np.float32), np.zeros(0, dtype=np.int64)
    m = bodies.axes / bodies.radii[:, :, None, :]  # (N, P, 3, 3)
    q = m @ m.transpose(0, 1, 3, 2)
    rel = o - bodies.centers  # (N, P, 3)
    qw = np.einsum("npij,npj->npi", q, rel)
    qc = (np.einsum("npi,npi->np", rel, qw) - 1.0).astype(np.float32)
    q6 = np.stack([q[..., 0, 0], q[..., 1, 1], q[..., 2, 2], 2 * q[..., 0, 1], 2 * q[..., 0, 2], 2 * q[..., 1, 2]], -1)
    q6, qw2 = q6.astype(np.float32), (2.0 * qw).astype(np.float32)
    qa, qb = np.empty((k, parts), np.float32), np.empty((k, parts), np.float32)
    cuts = np.flatnonzero(np.diff(who)) + 1
    for s, e in zip(np.r_[0, cuts].tolist(), np.r_[cuts, k].tolist(), strict=True):
        b = who[s]  # one small matrix product per body
        np.matmul(products[s:e], q6[b].T, out=qa[s:e])
        np.matmul(d[s:e], qw2[b].T, out=qb[s:e])
    disc = qb * qb
    disc -= 4.0 * qa * qc[who]
    hit = disc > 0
    np.sqrt(disc, out=disc, where=hit)
    t = -qb
    t -= disc
    t /= 2.0 * qa
    t[~(hit & (t > 1e-6))] = np.inf
    part = t.argmin(1)
    return t[np.arange(k), part], part


def ray_ellipsoids(o: FloatArray, d: FloatArray, centers: FloatArray, axes: FloatArray, radii: FloatArray) -> FloatArray:
    """Distances (K, P) along K rays from o to the first hit of P ellipsoids (inf: missed)."""
    to_unit = axes / radii[:, None, :]  # (P, 3, 3): world offsets to the unit sphere's frame
    o_local = np.einsum("pi,pij->pj", o - centers, to_unit)  # (P, 3)
    p = len(centers)
    d_local = (d @ to_unit.transpose(1, 0, 2).reshape(3, 3 * p)).reshape(len(d), p, 3)  # (K, P, 3)
    qa = np.einsum("kpj,kpj->kp", d_local, d_local)
    qb = 2.0 * np.einsum("kpj,pj->kp", d_local, o_local)
    qc = np.einsum("pj,pj->p", o_local, o_local) - 1.0
    disc = qb * qb - 4.0 * qa * qc
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (-qb - np.sqrt(disc)) / (2.0 * qa)
    return np.where((disc > 0) & (t > 1e-6), t, np.inf)


def ellipsoid_normals(points: FloatArray, centers: FloatArray, axes: FloatArray, radii: FloatArray) -> FloatArray:
    local = np.einsum("ki,kij->kj", points - centers, axes) / radii**2
    n = np.einsum("kij,kj->ki", axes, local)
    normals: FloatArray = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    return normals


def ray_pillar(o: FloatArray, d: FloatArray, p: Pillar) -> tuple[FloatArray, FloatArray]:
    """First hit of each ray with a vertical cylinder (side or top cap) and the surface normal."""
    rel = o[:2] - (p.x, p.y)
    a = (d[:, :2] ** 2).sum(1)
    b = 2.0 * d[:, :2] @ rel
    c = rel @ rel - p.radius**2
    disc = b * b - 4 * a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        t_side = (-b - np.sqrt(disc)) / (2 * a)
        z = o[2] + t_side * d[:, 2]
        side = (disc > 0) & (t_side > 0) & (z >= 0) & (z <= p.height)
        t_cap = (p.height - o[2]) / d[:, 2]
    t_cap = np.where(np.isfinite(t_cap), t_cap, -1.0)
    cap_xy = o[:2] + t_cap[:, None] * d[:, :2]
    cap = (t_cap > 0) & (((cap_xy - (p.x, p.y)) ** 2).sum(1) <= p.radius**2)
    t = np.where(side, t_side, np.inf)
    t = np.where(cap & (t_cap < t), t_cap, t)
    hit_xy = o[:2] + np.where(np.isfinite(t), t, 0.0)[:, None] * d[:, :2] - (p.x, p.y)
    side_normal = np.concatenate([hit_xy / p.radius, np.zeros((len(d), 1))], 1)
    normal = np.where((cap & (t == t_cap))[:, None], [[0.0, 0.0, 1.0]], side_normal)
    return t, normal


def ray_box(o: FloatArray, d: FloatArray, s: Shelf) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """First hit of each ray with a box standing on the floor, its normal and whether it is the top."""
    lo = np.array([min(s.x0, s.x1), min(s.y0, s.y1), 0.0])
    hi = np.array([max(s.x0, s.x1), max(s.y0, s.y1), s.height])
    with np.errstate(divide="ignore", invalid="ignore"):
        ta, tb = (lo - o) / d, (hi - o) / d
    t_near = np.fmin(ta, tb)
    t_far = np.fmax(ta, tb)
    t_near = np.where(np.isnan(t_near), -np.inf, t_near)
    t_far = np.where(np.isnan(t_far), np.inf, t_far)
    axis = t_near.argmax(1)
    t_in, t_out = t_near.max(1), t_far.min(1)
    hit = (t_in < t_out) & (t_in > 0)
    normal = np.zeros((len(d), 3))
    normal[np.arange(len(d)), axis] = -np.sign(d[np.arange(len(d)), axis])
    return np.where(hit, t_in, np.inf), normal, axis == 2
