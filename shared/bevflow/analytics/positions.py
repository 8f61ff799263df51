"""The input every analytics stage takes at a tick: track ids and feet positions, checked once.

Times are capture timestamps in integer nanoseconds, like every ``*_ns`` field of the wire
messages; positions are world metres on the floor. Track ids must be in [0, 2**31) so that a pair
of ids packs into one int64 key (see ``pair_keys``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bevflow.units import NS_PER_S

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

MAX_TRACK_ID = 2**31 - 1


def check_positions(ids: ArrayLike, xy: ArrayLike) -> tuple[IntArray, FloatArray]:
    """``ids`` as an (N,) int64 array and ``xy`` as (N, 2) float64, or a ValueError saying what is wrong."""
    ids_arr = np.asarray(ids)
    if ids_arr.size and not np.issubdtype(ids_arr.dtype, np.integer):
        raise ValueError(f"track ids must be integers, got dtype {ids_arr.dtype}")
    ids_arr = ids_arr.astype(np.int64).reshape(-1)
    xy_arr = np.asarray(xy, dtype=np.float64)
    if xy_arr.size == 0:
        xy_arr = xy_arr.reshape(0, 2)
    if xy_arr.ndim != 2 or xy_arr.shape[1] != 2:
        raise ValueError(f"positions must be an (N, 2) array of feet x, y in metres, got shape {xy_arr.shape}")
    if len(xy_arr) != len(ids_arr):
        raise ValueError(f"{len(ids_arr)} track ids but {len(xy_arr)} positions")
    if len(ids_arr) and (ids_arr.min() < 0 or ids_arr.max() > MAX_TRACK_ID):
        raise ValueError(f"track ids must lie in [0, {MAX_TRACK_ID}]")
    ordered = np.sort(ids_arr)
    if np.any(ordered[1:] == ordered[:-1]):
        repeated = np.unique(ordered[1:][ordered[1:] == ordered[:-1]])
        raise ValueError(f"track ids repeat within one tick: {repeated.tolist()}")
    if not np.isfinite(xy_arr).all():
        bad = ~np.isfinite(xy_arr).all(axis=1)
        raise ValueError(f"positions of tracks {ids_arr[bad].tolist()} are not finite")
    return ids_arr, xy_arr


def seconds_to_ns(seconds: float) -> int:
    return round(seconds * NS_PER_S)


def pair_keys(lo: IntArray, hi: IntArray) -> IntArray:
    """One int64 per (lo, hi) pair of track ids, ordered like the pairs themselves."""
    return (lo.astype(np.int64, copy=False) << 32) | hi.astype(np.int64, copy=False)


def pair_ids(keys: IntArray) -> IntArray:
    """The (K, 2) track-id pairs of ``pair_keys`` output."""
    return np.stack([keys >> 32, keys & 0xFFFFFFFF], axis=1).astype(np.int64).reshape(-1, 2)


class Clock:
    """Refuses a tick older than the previous one: analytics state only moves forward in time."""

    def __init__(self) -> None:
        self.last_ns: int | None = None

    def advance(self, time_ns: int) -> int:
        t = int(time_ns)
        if self.last_ns is not None and t < self.last_ns:
            raise ValueError(f"time went backwards: tick at {t} ns after one at {self.last_ns} ns")
        self.last_ns = t
        return t
