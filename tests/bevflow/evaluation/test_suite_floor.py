"""The paper suite, shortened, must keep scoring at least what it scored when the floors were set.

Like norfair's CI metrics file: ``suite_floor.json`` stores, for every (sequence, camera set,
method) row of a short run, a floor under MOTA and F1 and a ceiling over the tracking APE and the
per-box APE, a little looser than what the run measured. A change anywhere in the pipeline
(simulator, noise, projection, fusion, tracker, metrics) that makes a row worse fails here.

After an intended change, regenerate the file and review its diff:

    python tests/bevflow/evaluation/test_suite_floor.py --write
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import pytest

from bevflow.evaluation.suite import DEFAULT_NOISE, SuiteResult, run_suite

FLOOR_FILE = Path(__file__).with_name("suite_floor.json")
# Slack between what was measured and the stored bound: the run is deterministic, so this only
# absorbs floating-point differences between machines and tiny harmless changes.
SCORE_SLACK = 0.02  # MOTA and F1
APE_SLACK_M = 0.01  # tracking APE and box APE


def run_short_suite(frames_scale: float) -> SuiteResult:
    return run_suite("paper", frames_scale=frames_scale, noise=DEFAULT_NOISE, seed=0, processes=1)


def floors_from(result: SuiteResult) -> dict:
    rows = []
    for row in result.rows:
        r = row.record()
        rows.append({
            "seq": r["seq"], "cameras": r["cameras"], "method": r["method"],
            "MOTA_min": _bound(r["MOTA"], -SCORE_SLACK), "F1_min": _bound(r["F1"], -SCORE_SLACK),
            "APE_max": _bound(r["APE"], APE_SLACK_M), "box_APE_max": _bound(r["box_APE"], APE_SLACK_M),
        })  # fmt: skip
    return {"frames_scale": result.frames_scale, "seed": result.seed, "noise": result.as_dict()["noise"], "rows": rows}


def _bound(value: float, slack: float) -> float | None:
    """``value + slack``; None (no bound) where the short run had nothing to measure, e.g. the
    APE of a method that matched nobody."""
    return None if math.isnan(value) else round(value + slack, 3)


def to_json(floors: dict) -> str:
    """One row per line, so a regenerated file diffs row by row."""
    head = {k: v for k, v in floors.items() if k != "rows"}
    rows = ",\n".join("  " + json.dumps(row) for row in floors["rows"])
    return json.dumps(head)[:-1] + ', "rows": [\n' + rows + "\n]}\n"


def regressions(floors: dict, records: list[dict]) -> list[str]:
    """Every bound a record breaks, and every stored row the run did not produce."""
    found = {(r["seq"], tuple(r["cameras"]), r["method"]): r for r in records}
    broken = []
    for f in floors["rows"]:
        key = (f["seq"], tuple(f["cameras"]), f["method"])
        name = f"seq{key[0]} {'+'.join(key[1])} {key[2]}"
        r = found.get(key)
        if r is None:
            broken.append(f"{name}: row missing")
            continue
        checks = [("MOTA", r["MOTA"], ">=", f["MOTA_min"]), ("F1", r["F1"], ">=", f["F1_min"]),
                  ("APE", r["APE"], "<=", f["APE_max"]), ("box_APE", r["box_APE"], "<=", f["box_APE_max"])]  # fmt: skip
        for metric, value, op, bound in checks:
            if bound is None:
                continue
            ok = value is not None and not math.isnan(value) and (value >= bound if op == ">=" else value <= bound)
            if not ok:
                broken.append(f"{name}: {metric} {value} not {op} {bound}")
    return broken


@pytest.fixture(scope="module")
def floors() -> dict:
    return json.loads(FLOOR_FILE.read_text())


@pytest.fixture(scope="module")
def measured(floors: dict) -> list[dict]:
    result = run_short_suite(floors["frames_scale"])
    assert result.as_dict()["noise"] == floors["noise"], "the suite's default noise changed: regenerate the floors"
    return [row.record() for row in result.rows]


def test_every_row_stays_above_its_floor(floors: dict, measured: list[dict]) -> None:
    assert len(floors["rows"]) == 51  # (5 sequences x 3 camera sets + 2 x 1) x 3 methods
    broken = regressions(floors, measured)
    assert not broken, "suite regressed:\n" + "\n".join(broken)


@pytest.mark.parametrize(
    ("metric", "change"),
    [("MOTA", -0.05), ("F1", -0.05), ("APE", +0.05), ("box_APE", +0.05)],
)
def test_a_worse_row_is_caught(floors: dict, measured: list[dict], metric: str, change: float) -> None:
    worse = [dict(r) for r in measured]
    target = next(r for r in worse if r["seq"] == 4 and r["method"] == "cylinder")
    target[metric] += change
    broken = regressions(floors, worse)
    assert len(broken) == 1 and f"seq4 {'+'.join(target['cameras'])} cylinder: {metric}" in broken[0]


def test_a_missing_row_is_caught(floors: dict, measured: list[dict]) -> None:
    assert regressions(floors, measured[1:]) == ["seq1 cam1+cam2 cylinder: row missing"]


def main() -> None:
    parser = argparse.ArgumentParser(description="Regenerate the suite's stored floors from a fresh short run.")
    parser.add_argument("--write", action="store_true", help=f"write {FLOOR_FILE.name} (otherwise print it)")
    parser.add_argument("--frames-scale", type=float, default=None, help="run length (default: the stored one)")
    args = parser.parse_args()
    scale = args.frames_scale or json.loads(FLOOR_FILE.read_text())["frames_scale"]
    text = to_json(floors_from(run_short_suite(scale)))
    if args.write:
        FLOOR_FILE.write_text(text)
    else:
        print(text, end="")


if __name__ == "__main__":
    main()
