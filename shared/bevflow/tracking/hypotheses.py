"""Several ways of matching held open for a few seconds: decisions taken over several updates.

The online tracker (``bevflow.tracking.tracker``) matches tracks to detections from one update
alone. In a crowd that is sometimes the wrong call: two people pass 0.4 m apart, one steps 0.5 m
in a frame, and each lands nearer the other's predicted feet; the next few updates would have
shown who was who, but the swap is already made. ``HypothesisTracker`` keeps up to
``TrackerConfig.hypotheses`` trackers, each the outcome of a different sequence of matchings
(Reid's multiple hypothesis tracking, hypothesis-oriented, with N-scan pruning):

1. at each update every hypothesis offers its best matching of confirmed tracks to strong
   detections and up to ``BRANCHES`` − 1 runners-up costing at most ``MARGIN`` more
   (``Tracker.branch``: negative log-likelihoods, the runners-up from
   ``bevflow.metrics.ranked_matching``);
2. each choice makes a child hypothesis (a copy of the tracker updated with it), scored by the
   sum of its choices' costs since the hypotheses last agreed;
3. the ``hypotheses`` cheapest children within ``KEEP`` of the cheapest live on;
4. N-scan: whatever the best one decided more than ``hypothesis_window_s`` ago is final, so every
   hypothesis that decided otherwise then is dropped.

What the tracker reports is the best hypothesis's tracks at each update. When another hypothesis
overtakes it, the reported ids follow the better explanation of the last few seconds: a track may
change id, which is the swap undone. Inside, ids come from one counter for all hypotheses
(``Tracker.copy``), so no id is ever given to two tracks; most belong to hypotheses that lose.
What is reported carries ids of its own (``_PublishedIds``), given in sequence from ``first_id``
as each track is first reported, so that the ids a site sees count its people, not its
hypotheses (replaying CMC2 with 20, they confirmed 535 tracks, of which 30 were reported).

Where the tracks take the cameras' views themselves (``TrackerConfig.track_views``), a matching
gives each track at most one view of each camera (``bevflow.tracking.views``), and the hypotheses
differ in which view went to which track. Otherwise fusion takes the best hypothesis's predictions
as its priors (``bevflow.live.site_tracker``): fusing once per hypothesis scored the same on CMC2
at many times the cost.

On CMC2 (``docs/RESULTS.md``; four side cameras, 10 people at 4 fps) 20 hypotheses raised the
six perturbed copies' IDF1 0.529 → 0.610 and MOTA 0.862 → 0.877 (the output decided 2 s late:
0.619 and 0.902), and the tracker alone on the truth moved by 0.1 m IDF1 0.631 → 0.765.

The work grows with hypotheses × tracks, so it is kept down three ways: every choice is costed
before any copy is made, and only the children kept are made (``Tracker.branch``); the hypotheses
of one update share each group's ranking (``ranked_matchings``' memo), since they mostly hold the
same tracks; and past ``HYPOTHESIS_TRACKS`` tracks, fewer hypotheses are kept (``room``). Timed
at 10 fps on 16 cameras (``bevflow_services.benchmarks.tracking``), a site's tick with 20
took 16–18 ms for 100 people against 2.7–2.8 with one, and 20–22 ms for 1,000 people (one
hypothesis left) against 19–20; without the three, 63 and 740 ms in the same session. So 20 is
a site's default (``Thresholds.track_hypotheses``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from bevflow.detections import Cylinders
from bevflow.metrics.ranked_matching import RankingMemo
from bevflow.tracking.tracker import Fuse, IntArray, Tracker, TrackerConfig, TrackTable

BRANCHES = 5
"""Choices each hypothesis offers per update (the best and four runners-up)."""

MARGIN = 6.0
"""How much more (twice the negative log-likelihood) a runner-up may cost than the best choice: a
likelihood ratio of e⁻³. On CMC2's recording and six copies 3, 6 and 20 scored alike (IDF1 0.618,
0.624, 0.612); the wider, the more children in a calm crowd."""

KEEP = 6.0
"""How much more a hypothesis may cost than the best one and still be kept. 6 and 12 scored alike
on CMC2's recording and six copies (IDF1 0.617, 0.624); 12 does a third more work."""

HYPOTHESIS_TRACKS = 2000
"""Tracks times hypotheses that one update may hold: a site tracking more than this divided by
``TrackerConfig.hypotheses`` keeps fewer hypotheses (one from 2,000 tracks), so that the work per
update stays within a few times the plain tracker's however many people there are."""


@dataclass(eq=False)
class _Decision:
    """A hypothesis's update: when, the tracker it left (None before the first update; never
    moved again, since each update branches on copies), and the update before (None once this
    one is final)."""

    time_s: float
    tracker: Tracker | None
    before: _Decision | None


@dataclass(eq=False)
class _Hypothesis:
    cost: float
    tracker: Tracker
    decision: _Decision


@dataclass(eq=False)
class _PublishedIds:
    """Reported ids: the next in sequence for each hypothesis's id when a track is first reported
    (``ids``: hypothesis id → reported id). Ids of tracks no hypothesis holds any more are
    forgotten once the table has doubled since it was last cut back."""

    next_id: int
    ids: dict[int, int] = field(default_factory=dict)
    kept: int = 0

    def publish(self, tracks: TrackTable) -> TrackTable:
        own = tracks.id.tolist()
        for i in own:
            if i >= 0 and i not in self.ids:
                self.ids[i], self.next_id = self.next_id, self.next_id + 1
        return replace(tracks, id=np.array([self.ids[i] if i >= 0 else -1 for i in own], dtype=np.int64))

    def forget_unless(self, held: Callable[[], set[int]]) -> None:
        """Forget the ids not in ``held()`` (asked only when the table is due to be cut back)."""
        if len(self.ids) > 2 * self.kept + 256:
            still = held()
            self.ids = {i: published for i, published in self.ids.items() if i in still}
            self.kept = len(self.ids)


class HypothesisTracker:
    """The online tracker's interface over several hypotheses; see the module docstring.
    ``keep_final``: keep each update as it is made final, for ``final`` and ``finish`` (an
    evaluation's settled output); the live tracker asks for none and keeps none."""

    def __init__(self, config: TrackerConfig | None = None, first_id: int = 1, keep_final: bool = False,
                 fuse: Fuse | None = None) -> None:  # fmt: skip
        self.config = config or TrackerConfig()
        self.keep_final = keep_final
        self._fuse = fuse
        self._hypotheses = [_Hypothesis(0.0, Tracker(self.config, fuse=fuse), _Decision(float("-inf"), None, None))]
        self._final: list[tuple[float, TrackTable]] = []
        self._published = _PublishedIds(int(first_id))

    @property
    def best(self) -> Tracker:
        """The tracker of the likeliest hypothesis."""
        return self._hypotheses[0].tracker

    @property
    def next_id(self) -> int:
        """The id the next track reported will get (pass it as ``first_id`` on restart)."""
        return self._published.next_id

    @property
    def time_s(self) -> float | None:
        return self.best.time_s

    def reset(self) -> None:
        """Forget every track, hypothesis and the clock; ids keep counting from where they were."""
        self._hypotheses = [_Hypothesis(0.0, Tracker(self.config, fuse=self._fuse), _Decision(float("-inf"), None, None))]
        self._final = []
        self._published = _PublishedIds(self.next_id)

    def tracks(self, include_tentative: bool = False) -> TrackTable:
        return self._published.publish(self.best.tracks(include_tentative))

    def predicted(self, time_s: float, include_tentative: bool = False) -> Cylinders:
        return self.best.predicted(time_s, include_tentative)

    def view_keys(self) -> IntArray:
        return self.best.view_keys()

    def update(self, cylinders: Cylinders, time_s: float, sightings: Cylinders | None = None) -> TrackTable:
        """As ``Tracker.update``: the best hypothesis's tracks after every hypothesis took the
        cylinders seen at ``time_s``."""
        room = self.room()
        memo: RankingMemo = {}  # the hypotheses mostly hold the same tracks: each group ranked once
        options = []
        for parent in self._hypotheses:
            branches = parent.tracker.branch(cylinders, time_s, BRANCHES if room > 1 else 1, MARGIN, memo)
            options += [(parent.cost + choice.cost, parent, branches, choice) for choice in branches.choices]
        options.sort(key=lambda option: option[0])
        least = options[0][0]
        self._hypotheses = []
        for cost, parent, branches, choice in options[:room]:
            if cost - least <= KEEP:  # only the children kept are made
                tracker = branches.child(choice)
                self._hypotheses.append(_Hypothesis(cost, tracker, _Decision(float(time_s), tracker, parent.decision)))
        self._settle(float(time_s) - self.config.hypothesis_window_s)
        self._published.forget_unless(self._held_ids)
        return self._published.publish(self.best.report(sightings))

    def room(self) -> int:
        """How many hypotheses the next update keeps: ``TrackerConfig.hypotheses``, fewer where
        the best one holds more than ``HYPOTHESIS_TRACKS`` / ``hypotheses`` tracks, at least one."""
        return max(1, min(self.config.hypotheses, HYPOTHESIS_TRACKS // max(len(self.best), 1)))

    def final(self) -> list[tuple[float, TrackTable]]:
        """The updates made final since the last call, oldest first: (time, every track after
        it, tentative ones too), as the hypothesis that won saw them. Each update comes out once,
        ``hypothesis_window_s`` after it was made, or at ``finish``. Only with ``keep_final``."""
        if not self.keep_final:
            raise ValueError("HypothesisTracker.final needs keep_final=True: no final updates were kept")
        out, self._final = self._final, []
        return out

    def finish(self) -> list[tuple[float, TrackTable]]:
        """Make every update so far final, as the best hypothesis has it (the end of a
        recording), and return those ``final`` has not yet given."""
        self._settle(float("inf"))
        return self.final()

    def _settle(self, final_s: float) -> None:
        """Make the best hypothesis's decisions up to ``final_s`` final: keep only the hypotheses
        that took the same ones, forget what came before, and count costs from there."""
        settled = self._hypotheses[0].decision
        while settled.before is not None and settled.time_s > final_s:
            settled = settled.before
        self._hypotheses = [h for h in self._hypotheses if _descends(h.decision, settled)]
        newly, node = [], settled
        while node.before is not None:  # back to the last update made final before
            newly.append(node)
            node = node.before
        if self.keep_final:
            for decision in reversed(newly):
                if decision.tracker is not None:
                    tracks = decision.tracker.tracks(include_tentative=True)
                    self._final.append((decision.time_s, self._published.publish(tracks)))
        settled.before = None
        least = self._hypotheses[0].cost
        for hypothesis in self._hypotheses:
            hypothesis.cost -= least

    def _held_ids(self) -> set[int]:
        """The ids of every track a hypothesis holds, or held at an update not yet final."""
        held: set[int] = set()
        for hypothesis in self._hypotheses:
            decision: _Decision | None = hypothesis.decision
            while decision is not None and decision.tracker is not None:
                held.update(decision.tracker.tracks(include_tentative=True).id.tolist())
                decision = decision.before
        return held


def online_tracker(config: TrackerConfig, first_id: int = 1, keep_final: bool = False,
                   fuse: Fuse | None = None) -> Tracker | HypothesisTracker:  # fmt: skip
    """The tracker ``config`` asks for: several hypotheses (keeping their final updates where
    ``keep_final``), or the plain one. ``fuse``: as for ``Tracker``."""
    if config.hypotheses > 1:
        return HypothesisTracker(config, first_id, keep_final, fuse)
    return Tracker(config, first_id, fuse)


def final_updates(tracker: Tracker | HypothesisTracker, time_s: float) -> list[tuple[float, TrackTable]]:
    """After an update at ``time_s``, the updates made final by it (``HypothesisTracker.final``;
    the plain tracker's every update is final at once): what a late output is built from."""
    if isinstance(tracker, HypothesisTracker):
        return tracker.final()
    return [(time_s, tracker.tracks(include_tentative=True))]


def last_updates(tracker: Tracker | HypothesisTracker) -> list[tuple[float, TrackTable]]:
    """At the end of a recording, the updates not yet final (none for the plain tracker)."""
    return tracker.finish() if isinstance(tracker, HypothesisTracker) else []


def _descends(decision: _Decision, ancestor: _Decision) -> bool:
    node: _Decision | None = decision
    while node is not None and node is not ancestor:
        node = node.before
    return node is ancestor
