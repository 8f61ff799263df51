"""The gateway's degraded reasons: late ticks, skipped ticks, cameras down, behind or losing frames."""

from __future__ import annotations

import pytest

from bevflow_services.gateway.camera_health import CameraHealth
from bevflow_services.gateway.degraded import DataQuality, camera_reasons

S = 1_000_000_000
T0 = 1_700_000_000 * S


def camera(state: str = "up", behind_s: float = 0.1, frames: int = 100, dropped: int = 0, reason: str = "") -> CameraHealth:
    return CameraHealth(camera="north", state=state, reason=reason, received=frames, dropped=dropped, last_seq=frames,
                        last_capture_ns=T0, last_received_ns=T0 + int(behind_s * S), age_s=0.0,
                        recent_frames=frames, recent_dropped=dropped)


@pytest.mark.parametrize(
    ("health", "expected"),
    [
        (camera(), []),
        (camera(state="down", reason="stream closed"), ["camera north down: stream closed"]),
        (camera(behind_s=5.0), ["camera north is 5.0 s behind"]),
        (camera(frames=80, dropped=20), []),  # exactly the share allowed
        (camera(frames=70, dropped=30), ["camera north lost 30% of its frames recently"]),
        (camera(state="unknown", frames=0), []),
    ],
)
def test_camera_reasons(health: CameraHealth, expected: list[str]) -> None:
    assert camera_reasons([health], late_ns=3 * S, drop_share=0.2) == expected


def feed(quality: DataQuality, ticks: list[tuple[float, float]]) -> None:
    """(capture second, seconds until it arrived) per tick."""
    for capture_s, late_s in ticks:
        quality.tick(T0 + int(capture_s * S), T0 + int((capture_s + late_s) * S))


@pytest.mark.parametrize(
    ("ticks", "now_s", "expected"),
    [
        ([(t / 10, 0.2) for t in range(50)], 5.0, []),
        ([(t / 10, 0.2) for t in range(50)] + [(5.0, 4.0)], 9.0, ["tracks arrive 4.0 s after capture"]),
        ([(t / 10, 0.2) for t in range(20)] + [(4.0, 0.2), (4.1, 0.2)], 4.5, ["the tracker skipped ticks"]),
        ([(0.0, 0.2), (4.0, 0.2)] + [(4 + t / 10, 0.2) for t in range(1, 400)], 44.0, []),  # the gap is old news
    ],
)
def test_tick_reasons(ticks: list[tuple[float, float]], now_s: float, expected: list[str]) -> None:
    quality = DataQuality(late_s=3.0, gap_s=1.5, window_s=30.0)
    feed(quality, ticks)
    found = quality.reasons(T0 + int(now_s * S), [])
    assert [r.split(":")[0] for r in found] == expected


def test_degraded_periods_open_and_close() -> None:
    quality = DataQuality()
    assert quality.reasons(T0, [camera()]) == []
    assert quality.reasons(T0 + 2 * S, [camera(state="down", reason="gone")]) == ["camera north down: gone"]
    assert quality.reasons(T0 + int(2.5 * S), []) == ["camera north down: gone"]  # checked at most once a second
    assert [(p.start_ns, p.end_ns, p.reasons) for p in quality.periods] == [(T0 + 2 * S, None, ["camera north down"])]
    assert quality.reasons(T0 + 4 * S, [camera()]) == []
    assert [(p.start_ns, p.end_ns) for p in quality.periods] == [(T0 + 2 * S, T0 + 4 * S)]
