"""Chaos: the live system keeps its promises while its services are killed (SIGKILL) and restarted
one at a time, and while its router restarts.

One run (about 60 s) starts tracker, projector, recorder (SQLite), gateway and a simulated ingest
as separate processes, then kills and restarts ingest, projector, tracker, gateway and recorder in
turn. The test process watches the bus itself (it is the peers' meeting point, so it outlives every
service) and polls REST. Afterwards:

- every alert published on the bus is in the history the gateway serves, once, with its end;
- a restarted tracker does not hand out an id that the previous one used;
- after each restart, REST occupancy is back within tolerance of the simulator's truth in 2 s
  of capture time;
- then a forger on the bus (no bus password here) sends a tick dated 2262, one dated 1970 and a
  flood of alerts, some dated 2262 too: the live tracks go on, the far-future messages are
  refused and counted, and no real alert is lost.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from bevflow.schemas import DistanceViolation, Event, Occupancy, SimulatedTruth, Tracks
from bevflow.site import dump_site

from bevflow_services import bus
from bevflow_services.benchmarks.live import hall_site
from bevflow_services.launcher import Child, ServiceGroup, free_port
from tests.e2e.http import get_json

pytestmark = [pytest.mark.e2e, pytest.mark.slow]
PEOPLE = 16
TOLERANCE = max(3, PEOPLE // 5)  # as the end-to-end test: tracks confirm after 3 hits, die after 5 misses
RECOVERY_S = 2.0
KILL_ORDER = ("ingest", "projector", "tracker", "gateway", "recorder")
FAR_FUTURE_NS = 2**63 - 1
FORGED_ALERTS = 500  # well under the receivers' burst, so no real alert is refused meanwhile
S = 1_000_000_000


def chaos_site(folder: Path) -> Path:
    """Four cameras of the demo hall, with limits low enough that alerts come every few seconds."""
    site = hall_site(4)
    zones = [zone.model_copy(update={"capacity": 2, "crowded_level": 1}) for zone in site.zones]
    thresholds = site.thresholds.model_copy(update={
        "social_distance_m": 2.5, "violation_min_duration_s": 0.5, "group_walk_s": None, "group_after_s": None,
        "capacity_hysteresis": 0, "capacity_min_duration_s": 0.0})
    path = folder / "chaos-site.yaml"
    path.write_text(dump_site(site.model_copy(update={"site": "chaos", "zones": zones, "thresholds": thresholds})))
    return path


class MeetingGroup(ServiceGroup):
    """Services that meet through a session of the test (listening on ``hub_port``) rather than
    through the first service, so any service can die and come back."""

    def bus_args(self) -> list[str]:
        return ["--mode", "peer", "--listen", "tcp/127.0.0.1:0", "--connect", f"tcp/127.0.0.1:{self.hub_port}"]


class RoutedGroup(ServiceGroup):
    """Services in client mode through a router at ``hub_port``."""

    def bus_args(self) -> list[str]:
        return ["--mode", "client", "--connect", f"tcp/127.0.0.1:{self.hub_port}"]


@dataclass
class Observer:
    """Everything the site publishes that the checks need, received by the test's own session."""

    session: Any
    keys: bus.Keys
    lock: threading.Lock = field(default_factory=threading.Lock)
    events: dict[str, list[Any]] = field(default_factory=lambda: defaultdict(list))
    track_ids: list[tuple[int, set[int]]] = field(default_factory=list)  # (received, ids)
    truth: dict[int, int] = field(default_factory=dict)  # capture time -> people
    occupancy_ticks: list[int] = field(default_factory=list)  # received
    first_seen: dict[str, int] = field(default_factory=dict)  # alert id -> first received

    def __post_init__(self) -> None:
        self.subscriptions = [
            bus.subscribe(self.session, self.keys.events, bus.JsonCodec(Event, "Event"), self._on_event),
            bus.subscribe(self.session, self.keys.tracks, bus.JsonCodec(Tracks), self._on_tracks),
            bus.subscribe(self.session, self.keys.truth, bus.JsonCodec(SimulatedTruth), self._on_truth),
            bus.subscribe(self.session, self.keys.occupancy, bus.JsonCodec(Occupancy), self._on_occupancy),
        ]
        self.live = bus.LiveServices(self.session, self.keys)

    def _on_event(self, event: Any) -> None:
        with self.lock:
            self.events[event.id].append(event)
            self.first_seen.setdefault(event.id, time.time_ns())

    def _on_tracks(self, tracks: Tracks) -> None:
        with self.lock:
            self.track_ids.append((time.time_ns(), {t.id for t in tracks.tracks}))

    def _on_truth(self, truth: SimulatedTruth) -> None:
        with self.lock:
            self.truth[truth.capture_ns] = len(truth.tracks)

    def _on_occupancy(self, _occupancy: Occupancy) -> None:
        with self.lock:
            self.occupancy_ticks.append(time.time_ns())

    def truth_at(self, time_ns: int) -> int | None:
        with self.lock:
            if not self.truth:
                return None
            nearest = min(self.truth, key=lambda t: abs(t - time_ns))
            return self.truth[nearest] if abs(nearest - time_ns) < S // 5 else None

    def latest_events(self) -> dict[str, Any]:
        with self.lock:
            return {event_id: versions[-1] for event_id, versions in self.events.items()}

    def ids_between(self, start_ns: int, end_ns: int) -> set[int]:
        with self.lock:
            return set().union(*[ids for t, ids in self.track_ids if start_ns <= t < end_ns])

    def close(self) -> None:
        self.live.close()
        for subscription in self.subscriptions:
            subscription.close()


@dataclass
class RestPoller:
    """``/api/occupancy`` every ``period_s`` as (polled, capture time, total); errors (a gateway
    being restarted) are skipped."""

    url: str
    period_s: float = 0.2
    samples: list[tuple[int, int, int]] = field(default_factory=list)
    stop: threading.Event = field(default_factory=threading.Event)

    def __post_init__(self) -> None:
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.stop.wait(self.period_s):
            try:
                body = get_json(f"{self.url}/api/occupancy", timeout=1.0)
            except (OSError, ValueError):
                continue
            if body.get("time_ns") is None:  # a restarted gateway that has no occupancy yet
                continue
            self.samples.append((time.time_ns(), int(body["time_ns"]), int(body["total"])))

    def close(self) -> None:
        self.stop.set()
        self.thread.join()


def wait_until(condition, timeout_s: float, what: str, group: ServiceGroup) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            logs = "\n".join(f"--- {c.name}\n{c.log_tail(8)}" for c in group.children)
            raise AssertionError(f"{what} within {timeout_s:.0f} s; logs in {group.log_dir}\n{logs}")
        time.sleep(0.1)


def service_up(observer: Observer, service: str) -> bool:
    return service in {s.service for s in observer.live.current()}


def kill(child: Child) -> None:
    """SIGKILL the service and everything it started, as a crash or the OOM killer would."""
    os.killpg(child.process.pid, signal.SIGKILL)
    child.process.wait(10)


@dataclass
class Restart:
    service: str
    killed_ns: int
    up_ns: int
    recovered_s: float | None = None


@dataclass
class ChaosRun:
    observer: Observer
    poller: RestPoller
    group: ServiceGroup
    base: str
    restarts: list[Restart]
    events_before: dict[str, Any]
    history: list[dict[str, Any]]
    events_after: dict[str, Any]
    forged_ns: int
    health: dict[str, Any]


def recovery(run_samples: list[tuple[int, int, int]], observer: Observer, up_ns: int, until_ns: int) -> float | None:
    """Seconds of capture time from ``up_ns`` to the first REST total within tolerance of the
    truth, counting only data captured after the service came back."""
    for _polled, capture_ns, total in run_samples:
        if capture_ns < up_ns or capture_ns >= until_ns:
            continue
        expected = observer.truth_at(capture_ns)
        if expected is not None and abs(total - expected) <= TOLERANCE:
            return max(0.0, (capture_ns - up_ns) / S)
    return None


@pytest.fixture(scope="module")
def chaos(tmp_path_factory: pytest.TempPathFactory):
    folder = Path(tmp_path_factory.mktemp("chaos"))
    site = chaos_site(folder)
    group = MeetingGroup(site=str(site), log_dir=folder / "logs")
    keys = bus.Keys("chaos")
    session = bus.open_session(bus.BusConfig(mode="peer", listen=(f"tcp/127.0.0.1:{group.hub_port}",)))
    observer = Observer(session, keys)
    port, db = free_port(), folder / "history.db"
    args = {
        "tracker": ("--id-file", str(folder / "tracker-next-id")),
        "projector": (),
        "recorder": ("--db", str(db), "--commit-interval", "0.1"),
        # Loopback only, so no login: this test is about faults, not access control.
        "gateway": ("--port", str(port), "--db", str(db), "--no-view3d", "--auth", "off"),
        "ingest": ("--simulate", "--people", str(PEOPLE), "--seed", "3"),
    }
    base = f"http://127.0.0.1:{port}"
    poller = None
    try:
        children = {service: group.start(service, *args[service]) for service in args}
        wait_until(lambda: all(service_up(observer, s) for s in args), 60, "every service up", group)
        poller = RestPoller(base)
        wait_until(lambda: len(poller.samples) > 5 and recovery(poller.samples, observer, 0, 2**63) is not None,
                   30, "REST occupancy near the truth", group)
        wait_until(lambda: len(observer.latest_events()) >= 2, 30, "the first alerts", group)
        restarts = []
        for k, service in enumerate(KILL_ORDER):
            time.sleep(1.0)  # alerts happen while every service is up, too
            killed_ns = time.time_ns()
            kill(children[service])
            gone = f"{service}'s token gone after the kill"
            wait_until(lambda service=service: not service_up(observer, service), 10, gone, group)
            time.sleep(0.5)
            if service == "recorder":  # its restart must have alerts to fetch from the tracker's cache
                wait_until(lambda killed_ns=killed_ns: max(observer.first_seen.copy().values(), default=0) >= killed_ns,
                           30, "an alert raised while the recorder is down", group)
            children[service] = group.start(service, *args[service], name=f"{service}-restart-{k}")
            wait_until(lambda service=service: service_up(observer, service), 60, f"{service} back up", group)
            restart = Restart(service, killed_ns, time.time_ns())
            wait_until(lambda restart=restart: recovery(poller.samples, observer, restart.up_ns, 2**63) is not None, 20,
                       f"occupancy recovering after {service} restarted", group)
            restarts.append(restart)
        forged_ns = forge(session, keys)
        time.sleep(2.0)
        health = get_json(f"{base}/api/health")
        for restart, following in zip(restarts, [*restarts[1:], None], strict=True):
            until = following.killed_ns if following else 2**63
            restart.recovered_s = recovery(poller.samples, observer, restart.up_ns, until)
        events_before = observer.latest_events()
        time.sleep(1.0)  # the recorder commits every 0.1 s
        history = get_json(f"{base}/api/history/events?limit=10000")["items"]
        events_after = observer.latest_events()
        yield ChaosRun(observer, poller, group, base, restarts, events_before, history, events_after, forged_ns, health)
    finally:
        if poller is not None:
            poller.close()
        group.stop()
        observer.close()
        session.close()


def forge(session: Any, keys: bus.Keys) -> int:
    """What anyone on a bus without a password can send: ticks dated 2262 and 1970, and a flood
    of alerts (a tenth of them dated 2262). Returns when it started."""
    started = time.time_ns()
    with bus.Publication(session, keys.tracks, bus.JsonCodec(Tracks)) as ticks, \
            bus.Publication(session, keys.events, bus.JsonCodec(Event, "Event"), block_when_congested=True) as alerts:
        ticks.put(Tracks(site=keys.site, time_ns=FAR_FUTURE_NS))
        ticks.put(Tracks(site=keys.site, time_ns=0))
        for k in range(FORGED_ALERTS):
            start = FAR_FUTURE_NS if k % 10 == 0 else started
            alerts.put(DistanceViolation(id=f"forged-{k}", start_ns=start, tracks=[1, 2], min_distance_m=0.1, limit_m=2.0))
    return started


def test_no_service_stays_down(chaos: ChaosRun) -> None:
    live = {s["name"] for s in get_json(f"{chaos.base}/api/health")["services"]}
    assert set(KILL_ORDER) <= live
    assert [r.service for r in chaos.restarts] == list(KILL_ORDER)


def test_no_alert_is_lost_or_duplicated(chaos: ChaosRun) -> None:
    stored = [item["id"] for item in chaos.history]
    assert len(stored) == len(set(stored)), "an alert is stored twice"
    on_bus = set(chaos.events_before)
    assert len(on_bus) >= 5, f"too few alerts to judge: {sorted(on_bus)}"
    kinds = {event.type for event in chaos.events_before.values()}
    assert {"distance_violation", "over_capacity"} <= kinds, kinds
    missing = on_bus - set(stored)
    assert not missing, f"published on the bus but not in the history: {sorted(missing)}"
    assert set(stored) <= set(chaos.events_after), "the history holds alerts never published"


def test_alerts_raised_while_the_recorder_was_down_are_stored(chaos: ChaosRun) -> None:
    # The recorder fetches them from the tracker's cache when it comes back.
    restart = next(r for r in chaos.restarts if r.service == "recorder")
    while_down = {i for i, t in chaos.observer.first_seen.items() if restart.killed_ns <= t < restart.up_ns}
    print(f"alerts: {len(chaos.events_before)} on the bus, {len(while_down)} while the recorder was down")
    assert while_down, "the run raised no alert while the recorder was down"
    assert while_down <= {item["id"] for item in chaos.history}


def test_stored_alerts_have_their_ends(chaos: ChaosRun) -> None:
    stored = {item["id"]: item for item in chaos.history}
    ended = {i: e for i, e in chaos.events_before.items() if e.end_ns is not None}
    assert ended, "no alert ended during the run"
    wrong = {i: (stored[i].get("end_ns"), e.end_ns) for i, e in ended.items() if stored[i].get("end_ns") != e.end_ns}
    assert not wrong, f"(stored, published) ends differ: {wrong}"


def test_a_restarted_tracker_does_not_reuse_track_ids(chaos: ChaosRun) -> None:
    restart = next(r for r in chaos.restarts if r.service == "tracker")
    before = chaos.observer.ids_between(0, restart.killed_ns)
    after = chaos.observer.ids_between(restart.up_ns, 2**63)
    assert before and after
    assert not before & after, f"the restarted tracker handed out ids its predecessor used: {sorted(before & after)[:5]}"
    assert min(after) > max(before)


def test_counts_recover_within_two_seconds_of_each_restart(chaos: ChaosRun) -> None:
    recovered = {r.service: r.recovered_s for r in chaos.restarts}
    print("recovery after restart (s of capture time):", recovered)
    assert all(s is not None and s <= RECOVERY_S for s in recovered.values()), recovered


def test_the_restarted_gateway_serves_history_from_before_its_restart(chaos: ChaosRun) -> None:
    restart = next(r for r in chaos.restarts if r.service == "gateway")
    older = [item for item in chaos.history if item["start_ns"] < restart.killed_ns]
    assert older, "no alert from before the gateway's restart in its history"


def test_a_forged_far_future_tick_and_an_alert_flood_do_not_stop_the_site(chaos: ChaosRun) -> None:
    after = [(polled, capture) for polled, capture, _ in chaos.poller.samples if polled > chaos.forged_ns + S]
    assert after, "no REST sample after the forger"
    assert all(capture < chaos.forged_ns + 60 * S for _, capture in after)
    assert after[-1][1] > chaos.forged_ns, "the live data stopped at the forged tick"
    assert chaos.health["bus"]["rejected"].get("future_time", 0) >= 1 + FORGED_ALERTS // 10
    stored = {item["id"] for item in chaos.history}
    assert not {f"forged-{k}" for k in range(0, FORGED_ALERTS, 10)} & stored, "an alert dated 2262 was stored"
    assert all(item["start_ns"] < chaos.forged_ns + 60 * S for item in chaos.history)


# --- the router ----------------------------------------------------------------------------------
def test_services_reconnect_after_the_router_restarts(tmp_path: Path) -> None:
    site = chaos_site(tmp_path)
    group = RoutedGroup(site=str(site), log_dir=tmp_path / "logs")
    router_args = ("--listen", f"tcp/127.0.0.1:{group.hub_port}")
    keys = bus.Keys("chaos")
    port = free_port()
    base = f"http://127.0.0.1:{port}"

    def start_router(name: str) -> Child:
        # The router takes no --mode; start it as ServiceGroup does, with its own bus flags.
        child = ServiceGroup(site=str(site), log_dir=tmp_path / "logs", hub_port=group.hub_port)
        child.bus_args = lambda: []  # type: ignore[method-assign]
        started = child.start("router", *router_args, name=name)
        group.children.insert(0, started)
        wait_until(lambda: "listening on" in started.log_tail(), 30, f"{name} listening", group)
        return started

    router = start_router("router")
    session = None
    try:
        services = {
            "tracker": (), "projector": (), "gateway": ("--port", str(port), "--no-view3d", "--auth", "off"),
            "ingest": ("--simulate", "--people", str(PEOPLE)),
        }
        for service, extra in services.items():
            group.start(service, *extra)
        session = bus.open_session(bus.BusConfig(mode="client", connect=(f"tcp/127.0.0.1:{group.hub_port}",)))
        observer = Observer(session, keys)

        def fresh_occupancy(since_ns: int) -> bool:
            try:
                time_ns = get_json(f"{base}/api/occupancy", timeout=1.0)["time_ns"]
            except (OSError, ValueError):
                return False
            return time_ns is not None and time_ns > since_ns  # None: no occupancy has arrived yet

        wait_until(lambda: fresh_occupancy(0), 60, "occupancy through the router", group)
        kill(router)
        time.sleep(1.0)
        restarted_ns = time.time_ns()
        start_router("router-restarted")
        wait_until(lambda: fresh_occupancy(restarted_ns), 30, "occupancy after the router restarted", group)
        with observer.lock:
            observer.occupancy_ticks.clear()
        wait_until(lambda: len(observer.occupancy_ticks) > 5, 30, "the test's own client reconnected", group)
        live = {s["name"] for s in get_json(f"{base}/api/health")["services"]}
        assert set(services) <= live
        assert not [c.name for c in group.dead() if c is not router]
        observer.close()
    finally:
        group.stop()
        if session is not None:
            session.close()
