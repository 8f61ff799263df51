"""Every benchmark in one run, with one flat set of headline numbers that runs can be compared by.

``run_suite(settings, parts)`` runs the parts asked for, in order, and returns a JSON-ready dict:
the headline keys of ``HEADLINE_KEYS`` at the top level (a number, or null with its reason in
``null_reasons``), the machine it ran on, the settings, and each part's full results under
``parts``. A part that raises does not stop the others: its keys are null with the error as the
reason, and its name is listed in ``failed``.
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

from bevflow_services.benchmarks.timing import finite_or_none, machine

PARTS = ("cylinder", "tracking", "detector", "live", "gateway", "bus")
MAX_DENSITY = 1.0  # people per m²: denser tracking cases are a crush no site plans for, and are skipped


@dataclass(frozen=True)
class Settings:
    """How long each part runs. ``FULL`` for the numbers to keep, ``QUICK`` for about a minute."""

    cylinder_boxes: tuple[int, ...] = (10, 50, 200)
    cylinder_repeats: int = 50
    cylinder_reference_repeats: int = 3
    cylinder_reference_max_boxes: int | None = None
    tracking_people: tuple[int, ...] = (10, 100, 1000)
    tracking_cameras: tuple[int, ...] = (4, 16, 64)
    tracking_ticks: int = 100
    tracking_warmup: int = 20
    detector_repeats: int = 30
    live_duration_s: float = 30.0
    live_warmup_s: float = 5.0
    live_camera_steps: tuple[int, ...] = (4, 8, 16, 32, 64)
    live_probe_duration_s: float = 10.0
    live_bisect: bool = True
    live_detector_camera_steps: tuple[int, ...] = (1, 2, 4, 5, 6, 8)  # beyond the 6 a 2-core host should serve
    gateway_rate: float = 200.0
    gateway_duration_s: float = 20.0
    gateway_subscribers: int = 100
    bus_count: int = 300


FULL = Settings()
QUICK = Settings(
    cylinder_repeats=10, cylinder_reference_repeats=1, cylinder_reference_max_boxes=50, tracking_ticks=10,
    tracking_warmup=5, detector_repeats=3,
    live_duration_s=8.0, live_warmup_s=3.0, live_camera_steps=(4, 8), live_probe_duration_s=5.0, live_bisect=False,
    live_detector_camera_steps=(4,),
    gateway_duration_s=4.0, bus_count=30,
)  # fmt: skip

# The top-level keys every run writes, so runs can be compared (issue 8), and the part each comes from.
HEADLINE_KEYS: dict[str, str] = {
    "cylinder_batched_ms_per_box": "cylinder",
    "cylinder_batched_cpu_ms_per_box": "cylinder",
    "cylinder_reference_ms_per_box": "cylinder",
    "cylinder_speedup": "cylinder",
    "cylinder_max_disagreement_m": "cylinder",
    "tracking_ms_per_tick_1000_people_64_cameras": "tracking",
    "tracking_cpu_ms_per_tick_1000_people_64_cameras": "tracking",
    "detector_ms_per_frame_3_3m_2_threads": "detector",
    "detector_int8_speedup_5_5m_2_threads": "detector",
    "detector_workers_speedup_5_5m_2_cores": "detector",
    "detector_accelerator_speedup_5_5m_2_threads": "detector",
    "live_latency_p50_ms": "live",
    "live_latency_p99_ms": "live",
    "live_detector_latency_p50_ms": "live",
    "live_detector_latency_p99_ms": "live",
    "live_rendered_detector_latency_p99_ms": "live",
    "live_tracks_latency_p99_ms": "live",
    "live_frames_dropped_at_source": "live",
    "live_max_cameras_10fps": "live",
    "live_max_cameras_10fps_real_detector": "live",
    "gateway_rest_p50_ms": "gateway",
    "gateway_rest_p99_ms": "gateway",
    "gateway_ws_fanout_p50_ms": "gateway",
    "gateway_ws_fanout_p99_ms": "gateway",
    "bus_frame_p99_ms": "bus",
    "bus_json_p99_ms": "bus",
}

Headline = dict[str, object]


def run_cylinder(s: Settings) -> tuple[Headline, dict]:
    from bevflow_services.benchmarks.cylinder import bench_speed

    rows = bench_speed("fisheye-5.5", list(s.cylinder_boxes), s.cylinder_repeats, s.cylinder_reference_repeats,
                       reference_max_boxes=s.cylinder_reference_max_boxes)
    details: dict = {"camera": "fisheye-5.5", "rows": rows}
    head: Headline = {}
    if all(r["nan_mismatches"] == 0 for r in rows):
        head["cylinder_max_disagreement_m"] = max((r["max_disagreement_m"] for r in rows), default=None)
    else:  # a box one fit places and the other cannot is a disagreement no distance measures
        details["null_reasons"] = {"cylinder_max_disagreement_m": "the fits disagree on which boxes can be placed "
                                   f"({sum(r['nan_mismatches'] for r in rows)} boxes)"}
    at50 = next((r for r in rows if r["boxes"] == 50), None)
    if at50 is not None:
        head |= {"cylinder_batched_ms_per_box": at50["batched_ms_per_box"], "cylinder_batched_cpu_ms_per_box": at50["batched_cpu_ms_per_box"],
                 "cylinder_reference_ms_per_box": at50["reference_ms_per_box"], "cylinder_speedup": at50["speedup"]}  # fmt: skip
    return head, details


def run_tracking(s: Settings) -> tuple[Headline, dict]:
    from bevflow_services.benchmarks.tracking import CAMERA_SPACING_M, bench_tick

    rows, skipped = [], []
    for cameras in s.tracking_cameras:
        for people in s.tracking_people:
            density = people / (cameras * CAMERA_SPACING_M**2)
            if density > MAX_DENSITY:
                skipped.append({"people": people, "cameras": cameras, "why": f"{density:.1f} people/m² (a crush; limit {MAX_DENSITY:g})"})
                continue
            rows.append(bench_tick(people, cameras, s.tracking_ticks, s.tracking_warmup))
    big = next((r for r in rows if r["people"] == 1000 and r["cameras"] == 64), None)
    head: Headline = {}
    if big is not None:
        head = {"tracking_ms_per_tick_1000_people_64_cameras": big["ms_p50"], "tracking_cpu_ms_per_tick_1000_people_64_cameras": big["cpu_ms_p50"]}
    return head, {"rows": rows, "skipped": skipped}


def run_detector(s: Settings, model: Path | None) -> tuple[Headline, dict]:
    from bevflow_services.benchmarks.detector import bench_detector, bench_int8, bench_workers, lookup
    from bevflow_services.benchmarks.providers import bench_accelerators

    result = bench_detector(model, repeats=s.detector_repeats)
    if not result["available"]:
        raise Unavailable(result["reason"], result)
    import onnxruntime  # installed: the detector was timed

    # The shipped general model against its INT8 copy; a model of the user's own has none.
    int8 = bench_int8(rounds=max(1, s.detector_repeats // 3)) if model is None else {
        "available": False, "reason": "a model was given: it has no INT8 copy to time against"}
    # The detector service's workers against one frame at a time and against batches; the
    # shipped general model, as the service's default runs it.
    workers = bench_workers(rounds=max(1, s.detector_repeats // 6)) if model is None else {
        "available": False, "reason": "a model was given: the workers are timed with the shipped model"}
    # Each accelerator the installed ONNX Runtime build offers (the gpu or openvino extra) against the CPU.
    accelerators = bench_accelerators(onnxruntime.get_available_providers(), rounds=max(1, s.detector_repeats // 3)) \
        if model is None else {"available": False, "reason": "a model was given: accelerators are timed with the shipped models"}
    result["int8"], result["workers"], result["accelerators"] = int8, workers, accelerators
    parts = (("detector_int8_speedup_5_5m_2_threads", int8), ("detector_workers_speedup_5_5m_2_cores", workers),
             ("detector_accelerator_speedup_5_5m_2_threads", accelerators))
    result["null_reasons"] = {key: part["reason"] for key, part in parts if not part["available"]}
    return {"detector_ms_per_frame_3_3m_2_threads": lookup(result, 3.3, 2),
            "detector_int8_speedup_5_5m_2_threads": int8.get("speedup"),
            "detector_workers_speedup_5_5m_2_cores": workers.get("speedup"),
            "detector_accelerator_speedup_5_5m_2_threads": accelerators.get("speedup")}, result


def run_live(s: Settings) -> tuple[Headline, dict]:
    """The live system three times: with the simulator's boxes (the pipeline's own cost); with
    camera folders recorded before the run through the detector service (what a site with CPU
    detection gets); and with frames rendered during the run through it (as ``bevflow demo``
    runs, the renderer sharing the machine)."""
    from bevflow_services.benchmarks.live import max_cameras, measure

    latency = measure(s.live_duration_s, None, s.live_warmup_s, cameras=4)
    search = max_cameras(list(s.live_camera_steps), s.live_probe_duration_s, s.live_warmup_s, first=latency, bisect=s.live_bisect)
    detected = measure(s.live_duration_s, None, s.live_warmup_s, cameras=4, boxes="recorded")
    steps = list(s.live_detector_camera_steps)
    search_detected = max_cameras(steps, s.live_probe_duration_s, s.live_warmup_s, first=detected, bisect=False, boxes="recorded")
    rendered = measure(s.live_duration_s, None, s.live_warmup_s, cameras=4, boxes="rendered")
    head: Headline = {
        "live_latency_p50_ms": latency["live_latency_p50_ms"], "live_latency_p99_ms": latency["live_latency_p99_ms"],
        "live_detector_latency_p50_ms": detected["live_latency_p50_ms"],
        "live_detector_latency_p99_ms": detected["live_latency_p99_ms"],
        "live_rendered_detector_latency_p99_ms": rendered["live_latency_p99_ms"],
        "live_tracks_latency_p99_ms": latency["tracks_latency_p99_ms"],
        "live_frames_dropped_at_source": latency["frames_dropped_at_source"], "live_max_cameras_10fps": search["max_cameras"],
        "live_max_cameras_10fps_real_detector": search_detected["max_cameras"],
    }  # fmt: skip
    details = {"latency_4_cameras": latency, "max_cameras": search, "detector": "simulator boxes (no detector in the loop)",
               "detector_latency_4_cameras": detected, "detector_max_cameras": search_detected,
               "rendered_latency_4_cameras": rendered}
    details["null_reasons"] = {
        key: f"even {found['probes'][0]['cameras']} cameras were not kept up with: {found['probes'][0]['why']}"
        for key, found in (("live_max_cameras_10fps", search), ("live_max_cameras_10fps_real_detector", search_detected))
        if found["max_cameras"] is None
    }
    return head, details


def run_gateway(s: Settings) -> tuple[Headline, dict]:
    from bevflow_services.benchmarks.gateway import measure

    result = measure(s.gateway_rate, s.gateway_duration_s, s.gateway_subscribers, s.gateway_duration_s)
    head: Headline = {"gateway_rest_p50_ms": result["rest"]["p50_ms"], "gateway_rest_p99_ms": result["rest"]["p99_ms"],
                      "gateway_ws_fanout_p50_ms": result["websocket"]["p50_ms"], "gateway_ws_fanout_p99_ms": result["websocket"]["p99_ms"]}
    return head, result


def run_bus(s: Settings) -> tuple[Headline, dict]:
    from bevflow_services.benchmarks.bus import measure

    result = measure(["--count", str(s.bus_count)])
    return {"bus_frame_p99_ms": result["frame"]["p99_ms"], "bus_json_p99_ms": result["json"]["p99_ms"]}, result


class Unavailable(Exception):
    """A part that cannot run on this machine (no model, a missing package); not a failure."""

    def __init__(self, reason: str, details: dict | None = None) -> None:
        super().__init__(reason)
        self.reason, self.details = reason, details or {}


# Why the keys that are null by construction are null (none at present).
STANDING_REASONS: dict[str, str] = {}


def run_suite(settings: Settings, parts: tuple[str, ...] = PARTS, detector_model: Path | None = None,
              echo: Callable[[str], None] = print) -> dict:
    """Run ``parts`` with ``settings``; see the module docstring for what comes back."""
    runners: dict[str, Callable[[], tuple[Headline, dict]]] = {
        "cylinder": lambda: run_cylinder(settings), "tracking": lambda: run_tracking(settings),
        "detector": lambda: run_detector(settings, detector_model), "live": lambda: run_live(settings),
        "gateway": lambda: run_gateway(settings), "bus": lambda: run_bus(settings),
    }  # fmt: skip
    result: dict = {"machine": machine(), "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "settings": asdict(settings),
                    "parts_run": list(parts), "failed": [], "null_reasons": {}, "seconds": {}, "parts": {}}
    headline: Headline = {}
    for part in PARTS:
        keys = [k for k, p in HEADLINE_KEYS.items() if p == part]
        if part not in parts:
            result["null_reasons"] |= {k: f"the {part} part was not run" for k in keys}
            continue
        echo(f"-- {part} ...")
        start = time.monotonic()
        try:
            head, details = _run_part(runners[part])
        except Unavailable as exc:
            head, details = {}, {**exc.details, "reason": exc.reason}
            result["null_reasons"] |= {k: exc.reason for k in keys}
        except Exception as exc:  # one broken part must not cost the numbers of the others
            head, details = {}, {"error": traceback.format_exc()}
            result["failed"].append(part)
            result["null_reasons"] |= {k: f"the {part} part failed: {exc!r}" for k in keys}
        result["seconds"][part] = round(time.monotonic() - start, 1)
        result["null_reasons"] |= details.pop("null_reasons", {})
        result["parts"][part] = details
        headline |= head
    ordered: Headline = {}
    for key in HEADLINE_KEYS:
        value = headline.get(key)
        ordered[key] = value if isinstance(value, int) and not isinstance(value, bool) else finite_or_none(value)  # type: ignore[arg-type]
        if ordered[key] is None:
            reason = result["null_reasons"].get(key) or STANDING_REASONS.get(key) or "not measured (no finite value came out)"
            result["null_reasons"][key] = reason
        else:
            result["null_reasons"].pop(key, None)
    ready = json_ready({**ordered, **result})
    assert isinstance(ready, dict)  # json_ready keeps a dict a dict
    return ready


def _run_part(runner: Callable[[], tuple[Headline, dict]]) -> tuple[Headline, dict]:
    """``runner``'s result; a part whose optional dependency is not installed is ``Unavailable``,
    naming the extra (any other missing module is a failure)."""
    from bevflow_services import extras

    try:
        return runner()
    except ModuleNotFoundError as exc:
        extra = extras.extra_for(exc)
        if extra is None:
            raise
        raise Unavailable(f"this part {extras.install_hint(extra)}") from None


def json_ready(value: object) -> object:
    """``value`` with every NaN or infinity, however deep, replaced by None (strict JSON)."""
    if isinstance(value, float):
        return finite_or_none(value)
    if isinstance(value, dict):
        return {k: json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    return value
