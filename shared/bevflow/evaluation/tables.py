"""The suite's results as plain-text tables in the paper's layout (its Tables 2 and 3).

Table 2 has one row per sequence and camera set, for the cylinder method: MOTA, MT, PT, ML (as
fractions of the ground-truth tracks), FRAG, FRAG ratio, P, R, F1 and APE, then IDF1, the share
of ground truth no camera of the set boxed (``unseen``, a ceiling on recall) and the share of
person-frames in the area left out of the ground truth because no camera could see them at all
(``hidden``).
Table 3 compares the projection methods on P, R, F1 and APE (tracking APE: matched within the
0.5 m threshold, so it never exceeds it), and gives each method's mean floor error per detected
box (``box APE``, before fusion and tracking, not capped by any threshold) with the ratio of
bbox-centre's to the cylinder's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from bevflow.evaluation.suite import SuiteResult, SuiteRow

_TABLE3_METHODS = ("bbox-center", "nearest-point", "cylinder")


def format_suite(result: SuiteResult) -> str:
    """The settings line, Table 2 and Table 3."""
    n = result.noise
    head = (
        f"suite {result.suite}: frames x{result.frames_scale:g}, noise: jitter {n.jitter:g}, drop {n.drop:g}, "
        f"false positives {n.false_positives:g}, truncation {'on' if n.truncation else 'off'}, seed {result.seed}"
    )
    if result.detector:
        who = f"the detector {result.model}" if result.model else "the shipped detectors (by camera height)"
        head = f"suite {result.suite}: frames x{result.frames_scale:g}, boxes: {who} on rendered frames"
    return "\n\n".join([head, format_table2(result.rows), format_table3(result.rows)])


def format_table2(rows: Sequence[SuiteRow], method: str = "cylinder") -> str:
    """Tracking scores of one method (the paper's Table 2 uses the cylinder)."""
    header = (
        f"{'seq':>3} {'cameras':<11} {'MOTA':>6} {'MT':>5} {'PT':>5} {'ML':>5} {'FRAG':>5} {'FRAGr':>6} "
        f"{'P':>6} {'R':>6} {'F1':>6} {'APE m':>6} {'IDF1':>6} {'unseen':>6} {'hidden':>6}"
    )
    lines = [f"Table 2: tracking ({method})", header]
    for row in rows:
        if row.method != method:
            continue
        r = row.record()
        lines.append(
            f"{row.seq:>3} {_cameras(row):<11} {_n(r['MOTA'])} {_n(r['MT'], 5, 2)} {_n(r['PT'], 5, 2)} {_n(r['ML'], 5, 2)} "
            f"{r['FRAG']:>5} {_n(r['FRAG_ratio'], 6, 1)} {_n(r['P'])} {_n(r['R'])} {_n(r['F1'])} {_n(r['APE'])} "
            f"{_n(r['IDF1'])} {_n(r['unseen'])} {_n(r['hidden'])}"
        )
    return "\n".join(lines)


def format_table3(rows: Sequence[SuiteRow]) -> str:
    """P, R, F1 and APE of every projection method, then the uncapped error per box."""
    by_key: dict[tuple[int, tuple[str, ...]], dict[str, SuiteRow]] = {}
    for row in rows:
        by_key.setdefault((row.seq, row.cameras), {})[row.method] = row
    methods = [m for m in _TABLE3_METHODS if any(m in found for found in by_key.values())]
    group = " | ".join(f"{m:^27}" for m in methods)
    cols = " | ".join(f"{'P':>6} {'R':>6} {'F1':>6} {'APE':>6}" for _ in methods)
    box_cols = " ".join(f"{m:>13}" for m in methods)
    lines = ["Table 3: projection methods (APE: tracking, matched within 0.5 m; box APE: every detected box, m)",
             f"{'':>3} {'':<11} {group} | {'box APE':^{14 * len(methods) - 1}} {'bbox/cyl':>8}",
             f"{'seq':>3} {'cameras':<11} {cols} | {box_cols} {'':>8}"]  # fmt: skip
    for (seq, cameras), found in by_key.items():
        cells = []
        for m in methods:
            r = found[m].record() if m in found else None
            cells.append(" ".join(_n(r[k]) if r else f"{'':>6}" for k in ("P", "R", "F1", "APE")))
        boxes = " ".join(_n(found[m].box_ape, 13) if m in found else f"{'':>13}" for m in methods)
        ratio = math.nan
        if "bbox-center" in found and "cylinder" in found and found["cylinder"].box_ape > 0:
            ratio = found["bbox-center"].box_ape / found["cylinder"].box_ape
        lines.append(f"{seq:>3} {'+'.join(cameras):<11} {' | '.join(cells)} | {boxes} {_n(ratio, 8, 1)}")
    return "\n".join(lines)


def _cameras(row: SuiteRow) -> str:
    return "+".join(row.cameras)


def _n(value: float, width: int = 6, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return f"{'-':>{width}}"
    return f"{value:>{width}.{digits}f}"
