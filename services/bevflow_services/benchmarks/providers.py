"""The detector on other ONNX Runtime execution providers against the CPU's own, in one process.

Each case (the general model and its INT8 copy at 5.5 m, the rim tiles at 3.3 m on a real
camera's 2048² frame) is loaded once per provider list and timed in alternating rounds
(``detector.alternately``), so every list sees the same machine load; the CPU alone is always the
first list, the baseline. It measures what the installed build offers: run it in an install with
the ``openvino`` or ``gpu`` extra (docs/INSTALL.md). A list whose accelerator did not load runs on
the CPU, and its row says so (``loaded``), so a fallback is never timed as the accelerator.
``bevflow bench`` runs ``bench_accelerators``: every accelerator the installed build offers.

    python -m bevflow_services.benchmarks.providers openvino,cpu [cuda,cpu ...] [--threads 2]
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from bevflow.detect.providers import PROVIDERS, check_providers

from bevflow_services.benchmarks.detector import alternately, camera_sized, frame_for

if TYPE_CHECKING:
    from bevflow.detect.runtime import Detector
    from bevflow.detect.tiles import RimTileDetector

# (case, camera height m): the models the detector serves by default, and the INT8 copy.
CASES = (("general model, float32", 5.5), ("general model, INT8", 5.5), ("rim tiles", 3.3))
BASELINE = ("cpu",)
ACCELERATORS = tuple(name for name in PROVIDERS if name not in BASELINE)

MakeDetector = Callable[[str, Sequence[str], int], "Detector | RimTileDetector"]


def make_detector(case: str, providers: Sequence[str], threads: int) -> Detector | RimTileDetector:
    """The shipped detector of ``case`` on ``providers``."""
    from bevflow.detect.runtime import DEFAULT_MODEL, INT8_MODEL, Detector
    from bevflow.detect.tiles import load_rim_tiles

    if case == "rim tiles":
        return load_rim_tiles(threads, providers=providers)
    return Detector(INT8_MODEL if "INT8" in case else DEFAULT_MODEL, threads=threads, providers=providers)


def loaded_providers(detector: Detector | RimTileDetector) -> list[str]:
    """The providers a detector's session runs on (a rim-tile detector: its tiles' model's)."""
    return list(getattr(getattr(detector, "tile_detector", detector), "providers", []))


def bench_providers(candidates: Sequence[Sequence[str]], threads: int = 2, rounds: int = 10, calls: int = 3,
                    make: MakeDetector = make_detector) -> list[dict]:
    """One row per case: median ms per frame on each provider list (the CPU's first) and the
    providers each list's sessions loaded."""
    wanted = dict.fromkeys(tuple(check_providers(c)) for c in candidates)  # each list once, in order
    lists = [BASELINE, *(names for names in wanted if names != BASELINE)]
    rows = []
    for case, height in CASES:
        detectors = {",".join(names): make(case, names, threads) for names in lists}
        frame, focal = camera_sized(next(iter(detectors.values())), *frame_for(height))
        ms = alternately(detectors, frame, height, focal, rounds, calls)
        rows.append({"case": case, "height_m": height, "threads": threads, "frame": f"{frame.shape[1]}x{frame.shape[0]}",
                     "ms_p50": {k: round(v, 2) for k, v in ms.items()},
                     "loaded": {k: loaded_providers(d) for k, d in detectors.items()}})
    return rows


def bench_accelerators(available: Sequence[str], rounds: int = 10, calls: int = 3, make: MakeDetector = make_detector) -> dict:
    """Each accelerator of ``available`` (``onnxruntime.get_available_providers()``) against the
    CPU (``bench_providers``), and ``speedup``: the CPU's ms per frame of the float32 general model
    at 5.5 m over that of the fastest accelerator whose session loaded it. Unavailable, with the
    reason, where the build offers none (the cpu extra) or none loaded."""
    offered = [name for name in ACCELERATORS if PROVIDERS[name] in available]
    if not offered:
        return {"available": False, "reason": "this onnxruntime build offers no accelerator (the cpu extra; "
                "the gpu and openvino extras do, docs/INSTALL.md)"}
    rows = bench_providers([[name, "cpu"] for name in offered], rounds=rounds, calls=calls, make=make)
    general = rows[0]  # CASES[0]: the float32 general model
    loaded = [f"{name},cpu" for name in offered if PROVIDERS[name] in general["loaded"][f"{name},cpu"]]
    if not loaded:
        return {"available": False, "rows": rows,
                "reason": f"{', '.join(offered)} offered by this onnxruntime build but not loaded (no device or driver?)"}
    best = min(loaded, key=lambda key: general["ms_p50"][key])
    return {"available": True, "rows": rows, "best": best,
            "speedup": round(general["ms_p50"]["cpu"] / general["ms_p50"][best], 3) if general["ms_p50"][best] > 0 else None}


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description="The detector on execution providers against the CPU's, alternately.")
    parser.add_argument("providers", nargs="+", help="provider lists to time, e.g. openvino,cpu cuda,cpu")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=10, help="alternating rounds of 3 calls each")
    args = parser.parse_args(argv)
    try:
        rows = bench_providers([text.split(",") for text in args.providers], args.threads, args.rounds)
    except ValueError as exc:  # an unknown provider, refused before anything loads
        parser.error(str(exc))
    print(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
