from __future__ import annotations

from bevflow_services.benchmarks.bus import measure


def test_both_kinds_of_message_cross_to_a_child_process() -> None:
    result = measure(["--count", "5", "--warmup", "2", "--timeout", "30"])
    assert set(result) == {"frame", "json"}
    for kind, r in result.items():
        assert r["sent"] == 5 and r["received"] == 5, kind
        assert 0 < r["p50_ms"] <= r["p99_ms"] <= r["max_ms"]
