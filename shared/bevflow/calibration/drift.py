"""Noticing, live, that a camera has moved since it was calibrated (bumped, re-mounted, sagging).

Every tick, the cylinders that two overlapping cameras see of one person *alone* in their overlap
give one offset sample: camera a's feet minus camera b's (``isolated_pairs``). The pairing is the
monitor's own, with a 1 m gate, not fusion's: fusion's 0.45 m gate cuts the offsets off, and two
well calibrated cameras already disagree by 0.3 m in the simulator (each camera's cylinder fits
lean toward it), so a shift would mostly starve fusion's pairs instead of moving them. Per camera
pair the monitor keeps:

- a *baseline*: the pair's offset over its first ``warmup_s`` seconds of samples;
- a *current* offset: over the samples of the last ``window_s`` seconds.

Both are medians (or interquartile means, ``statistic="iqm"``: as robust, a little less noisy), not
means: a wrong pairing gives one wild sample, which must not count. The systematic disagreement of
a pair is in its baseline, so only a *change* counts: a pair has *shifted* when current and
baseline differ by more than ``shift_m``, and is *stable* when they differ by less than half of it.

Which camera moved? A moved camera shifts every pair it belongs to, while the other pairs of its
neighbours stay stable. So a camera is a suspect when it is in a shifted pair and in no stable
pair, and the suspects that explain the most shifted pairs are named first. Two suspects that
explain the same pairs are told apart by their other pairs, so the monitor waits while any of those
is undecided. Two cameras that overlap only each other cannot be told apart; the event then names
the later in site order, with the other as ``reference_camera``. A camera is named only after it
has stayed the explanation for ``confirm_s``: right after a move, the moved camera's pairs ramp up
at different rates inside the window, and for a moment the slower one can look stable.

Each camera gets one ``CalibrationDrift`` event when it is first named (``start_ns``; ``shift_m``
is its most shifted pair's change), and the same event again with ``end_ns`` once all its pairs
are stable again. After recalibrating a camera, call ``reset(camera_id)`` so its pairs learn a new
baseline.

How small a move is seen depends on the mounting height (a 2° tilt moves the floor estimates
about 0.1 m in a 4 m hall and 0.2 m at 5.5 m, in the simulator) and on the noise of the window,
which falls with the number of different people crossing the overlap in ``window_s``.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from bevflow.calibration.consistency import isolated_pairs
from bevflow.detections import Cylinders
from bevflow.schemas import CalibrationDrift

FloatArray = NDArray[np.float64]
Pair = tuple[int, int]


@dataclass(frozen=True)
class DriftConfig:
    """``warmup_s``: how long a pair collects samples before its baseline is fixed; ``window_s``:
    how far back the current offset looks; each needs at least ``min_samples``. ``shift_m``: the
    change of a pair's offset that counts as a shift (half of it counts as stable).
    ``pair_gate_m``: how far apart two cameras' cylinders may be to pair (``isolated_pairs``).
    ``evaluate_every_s``: how often the pairs are judged; samples are taken every tick.
    ``confirm_s``: how long a camera must stay the explanation of its shifted pairs before it is
    named."""

    warmup_s: float = 300.0
    window_s: float = 120.0
    min_samples: int = 50
    shift_m: float = 0.10
    pair_gate_m: float = 1.0
    statistic: Literal["median", "iqm"] = "median"
    evaluate_every_s: float = 1.0
    confirm_s: float = 15.0

    def __post_init__(self) -> None:
        if not (self.warmup_s >= 0 and self.window_s > 0 and self.min_samples >= 1 and self.evaluate_every_s >= 0
                and self.confirm_s >= 0):
            raise ValueError("warmup_s, evaluate_every_s and confirm_s must be >= 0, window_s > 0 and min_samples >= 1")
        if not (self.shift_m > 0 and self.pair_gate_m > self.shift_m):
            raise ValueError(f"need 0 < shift_m < pair_gate_m, got {self.shift_m} and {self.pair_gate_m}")


@dataclass
class _PairTrack:
    """Offsets of one camera pair: the warm-up samples until the baseline is fixed, then the
    samples of the last ``window_s`` seconds."""

    first_ns: int
    warmup: list[FloatArray] = field(default_factory=list)
    baseline: FloatArray | None = None
    baseline_ns: int = 0
    latest_ns: int = 0
    recent: deque[tuple[int, FloatArray]] = field(default_factory=deque)  # (tick time, its offsets)
    recent_count: int = 0

    def add(self, time_ns: int, offsets: FloatArray, config: DriftConfig) -> None:
        self.latest_ns = time_ns
        if self.baseline is None:
            self.warmup.extend(offsets)
            if time_ns - self.first_ns >= config.warmup_s * 1e9 and len(self.warmup) >= config.min_samples:
                self.baseline = _centre(np.array(self.warmup), config.statistic)
                self.baseline_ns = time_ns
                self.warmup = []
            return
        self.recent.append((time_ns, offsets))
        self.recent_count += len(offsets)
        while time_ns - self.recent[0][0] > config.window_s * 1e9:
            self.recent_count -= len(self.recent.popleft()[1])

    def shift(self, config: DriftConfig) -> float | None:
        """How far the current offset is from the baseline, once both are known: a window of a
        few seconds would hold only the two or three people who happened to be there."""
        if self.baseline is None or self.recent_count < config.min_samples:
            return None
        if self.latest_ns - self.baseline_ns < config.window_s * 1e9:
            return None
        current = _centre(np.concatenate([o for _, o in self.recent]), config.statistic)
        return float(np.linalg.norm(current - self.baseline))


def _centre(offsets: FloatArray, statistic: str) -> FloatArray:
    if statistic == "median":
        return np.median(offsets, axis=0)
    # Interquartile mean per component: as robust to a few wild samples as the median, less noisy.
    lo, hi = np.percentile(offsets, [25, 75], axis=0)
    inside = (offsets >= lo) & (offsets <= hi)
    mean: FloatArray = (offsets * inside).sum(axis=0) / np.maximum(inside.sum(axis=0), 1)
    return mean


@dataclass(frozen=True)
class PairDrift:
    """A pair's state, for diagnostics: ``shift_m`` is None until baseline and window are known."""

    camera_a: str
    camera_b: str
    baseline: tuple[float, float] | None
    shift_m: float | None
    window_samples: int


class DriftMonitor:
    """Running per-pair offset statistics and ``CalibrationDrift`` events; see the module notes.

    >>> monitor = DriftMonitor(["cam-a", "cam-b", "cam-c"])
    >>> monitor.update(0, Cylinders.empty())
    []
    """

    def __init__(self, camera_ids: Sequence[str], config: DriftConfig | None = None) -> None:
        self.camera_ids = list(camera_ids)
        self.config = config or DriftConfig()
        self._pairs: dict[Pair, _PairTrack] = {}
        self._active: dict[int, CalibrationDrift] = {}
        self._suspected_ns: dict[int, int] = {}  # camera -> since when it has been the explanation
        self._evaluated_ns: int | None = None

    def update(self, time_ns: int, cylinders: Cylinders) -> list[CalibrationDrift]:
        """Take one tick's per-camera cylinders (before fusion; ``camera`` indexes ``camera_ids``)
        and return the drift events that start or end now."""
        samples = isolated_pairs(cylinders, self.config.pair_gate_m)
        for a, b in {(int(a), int(b)) for a, b in zip(samples.a, samples.b, strict=True)}:
            track = self._pairs.setdefault((a, b), _PairTrack(first_ns=time_ns))
            track.add(time_ns, samples.offset[(samples.a == a) & (samples.b == b)], self.config)
        # Drift is slow and the medians are not free: judge once per evaluate_every_s.
        if self._evaluated_ns is not None and time_ns - self._evaluated_ns < self.config.evaluate_every_s * 1e9:
            return []
        self._evaluated_ns = time_ns
        return self._events(time_ns)

    def reset(self, camera_id: str | None = None) -> None:
        """Forget the baselines of ``camera_id``'s pairs (every pair when None); they are learnt
        again from the next samples. Any open event of that camera is dropped without an end."""
        index = None if camera_id is None else self.camera_ids.index(camera_id)
        for pair in [p for p in self._pairs if index is None or index in p]:
            del self._pairs[pair]
        for cam in [c for c in self._active if index is None or c == index]:
            del self._active[cam]
        self._suspected_ns = {c: t for c, t in self._suspected_ns.items() if index is not None and c != index}

    @property
    def active(self) -> list[CalibrationDrift]:
        """The drift events not yet ended."""
        return list(self._active.values())

    def pairs(self) -> list[PairDrift]:
        """Every camera pair seen so far, in site order."""
        return [
            PairDrift(
                camera_a=self.camera_ids[a],
                camera_b=self.camera_ids[b],
                baseline=None if track.baseline is None else (float(track.baseline[0]), float(track.baseline[1])),
                shift_m=track.shift(self.config),
                window_samples=track.recent_count,
            )
            for (a, b), track in sorted(self._pairs.items())
        ]

    def _events(self, time_ns: int) -> list[CalibrationDrift]:
        shifts = {p: s for p, t in self._pairs.items() if (s := t.shift(self.config)) is not None}
        # Pairs of a camera already named are explained by it until it is back, whatever they do.
        open_pairs = {p: s for p, s in shifts.items() if not set(p) & set(self._active)}
        named = _explain(open_pairs, self.config.shift_m)
        # While a moved camera's pairs ramp up inside the window, the slower one can still look
        # stable for a moment and clear it, so that its neighbour looks guilty: name a camera only
        # once it has stayed the explanation for confirm_s.
        self._suspected_ns = {cam: self._suspected_ns.get(cam, time_ns) for cam in named}
        events = []
        for cam, pair in named.items():
            if cam not in self._active and time_ns - self._suspected_ns[cam] >= self.config.confirm_s * 1e9:
                event = CalibrationDrift(
                    id=f"calibration-drift-{self.camera_ids[cam]}-{time_ns}",
                    start_ns=time_ns,
                    camera=self.camera_ids[cam],
                    shift_m=shifts[pair],
                    reference_camera=self.camera_ids[pair[0] if pair[1] == cam else pair[1]],
                )
                self._active[cam] = event
                events.append(event)
        for cam, event in list(self._active.items()):
            mine = [s for p, s in shifts.items() if cam in p]
            if cam not in named and mine and all(s < self.config.shift_m / 2 for s in mine):
                events.append(event.model_copy(update={"end_ns": time_ns}))
                del self._active[cam]
        return events


def _explain(shifts: dict[Pair, float], shift_m: float) -> dict[int, Pair]:
    """The cameras to blame for the shifted pairs, each with its most shifted pair.

    Suspects are cameras in a shifted pair and in no stable pair. The suspect explaining the most
    shifted pairs is named first. When suspects tie and one of them still has a pair between
    stable and shifted, the data cannot tell them apart yet, so nobody is named for those pairs;
    when neither has any other pair to wait for, the later camera is named (module notes)."""
    shifted = {p for p, s in shifts.items() if s > shift_m}
    stable = {p for p, s in shifts.items() if s < shift_m / 2}
    unsure = set(shifts) - shifted - stable
    suspects = {c for p in shifted for c in p} - {c for p in stable for c in p}
    uncovered = set(shifted)
    named: dict[int, Pair] = {}
    while uncovered:
        covering = {c: {p for p in uncovered if c in p} for c in suspects - set(named)}
        covering = {c: ps for c, ps in covering.items() if ps}
        if not covering:
            break
        most = max(len(ps) for ps in covering.values())
        tied = sorted(c for c, ps in covering.items() if len(ps) == most)
        if len(tied) > 1 and any(c in p for c in tied for p in unsure):
            uncovered -= set().union(*(covering[c] for c in tied))  # wait for those pairs to settle
            continue
        cam = tied[-1]
        named[cam] = max((p for p in shifted if cam in p), key=lambda p: (shifts[p], p))
        uncovered -= covering[cam]
    return named
