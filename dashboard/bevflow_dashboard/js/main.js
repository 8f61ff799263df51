// The dashboard's wiring: load the site, open the live streams, poll the slower REST views, and
// route clicks between the map, the lists and the person panel.
//
// `window.bevflow` exposes a few live counts for browser tests and for support staff checking a
// screen from the devtools console; the page itself never reads it.

import { AlertFeed } from "./alerts.js";
import { LiveSocket, every, getJson } from "./api.js";
import { Notifier } from "./notify.js";
import { OccupancyChart } from "./chart.js";
import { ConnectionMonitor } from "./connection.js";
import { el } from "./dom.js";
import { alertLabel, clockTime, dateFromNs } from "./format.js";
import { renderCameras, renderDegraded, renderServices, renderStatus } from "./health.js";
import { FloorMap } from "./map.js";
import { occupancyFromTracks, renderOccupancy } from "./occupancy.js";
import { PeopleList } from "./people.js";
import { PersonPanel } from "./person.js";
import { showSession } from "./session.js";

const $ = (id) => document.getElementById(id);
const LIMITS_MS = 10000; // capacities and crowded levels: they change only with the site file
const HEALTH_MS = 3000;
const HISTORY_MS = 15000;
const PEOPLE_LIST_MS = 500; // the list is for finding someone, not for watching them move

const debug = { ready: false, people: 0, violations: 0, alerts: 0, attention: 0, selected: null, focused: null, trajectory: 0, screenOf: () => null };
window.bevflow = debug;

const monitor = new ConnectionMonitor($("connection-banner"), $("connection-detail"), {
  onChange: (live) => live || renderStatus($("system-status"), "down"),
});

/** Retry `load` with backoff until it works (the gateway may be starting or restarting). */
async function untilLoaded(load) {
  for (let attempt = 0; ; attempt++) {
    try {
      const result = await load();
      monitor.ok("rest");
      return result;
    } catch (error) {
      const waitMs = Math.min(10000, 500 * 2 ** attempt);
      monitor.lost("rest", `${error.message}; retrying in ${Math.ceil(waitMs / 1000)} s.`);
      await new Promise((resolve) => setTimeout(resolve, waitMs));
    }
  }
}

/** A REST poll that reports failures to the banner instead of throwing. */
function polled(task) {
  return async () => {
    try {
      await task();
      monitor.ok("rest");
    } catch (error) {
      monitor.lost("rest", `The gateway does not answer (${error.message}).`);
      throw error;
    }
  };
}

async function boot() {
  const [site, config] = await untilLoaded(() => Promise.all([getJson("/api/site"), getJson("/api/config")]));
  const zones = new Map(site.zones.map((z) => [z.id, z]));
  const zoneName = (id) => zones.get(id)?.name || id;
  $("site-name").textContent = site.site;
  await showSession({ badge: $("session"), calibrationLink: $("calibration-link") });
  let latestNs = null;
  let selected = null;

  const map = new FloorMap($("map"), { onSelect: (id) => select(id) });
  map.setSite(site);
  debug.screenOf = (id) => map.screenOf(id);
  const chart = new OccupancyChart($("chart"));
  const people = new PeopleList($("people-list"), $("people-count"), { zoneName, onSelect: (id) => select(id) });
  const panel = new PersonPanel(
    {
      panel: $("person-panel"),
      section: $("person-panel").closest("section"),
      title: $("person-title"),
      closeButton: $("person-close"),
      facts: $("person-facts"),
      contactsBody: $("contacts-body"),
      contactsTable: $("contacts-table"),
      contactsEmpty: $("contacts-empty"),
      contactsLimit: $("contacts-limit"),
    },
    {
      zoneName,
      onTrack: (id) => select(id),
      onTrajectory: (id, points) => {
        if (id !== selected) return;
        map.select(id, points);
        debug.trajectory = points.length;
      },
      onClose: () => {
        selected = debug.selected = null;
        debug.trajectory = 0;
        map.select(null);
        people.select(null);
      },
    },
  );
  const notifier = new Notifier($("notify"));
  const feed = new AlertFeed(
    {
      list: $("alert-list"), empty: $("alerts-empty"), count: $("alerts-count"), announcer: $("alert-announcer"),
      showEnded: $("show-ended"), held: $("alerts-held"), ackAll: $("ack-all"),
    },
    {
      site: site.site, zoneName, onTrack: (id) => select(id), onChange: showAttention,
      onArrive: (alert) => {
        notifier.consider(alert, `${alertLabel(alert.type)}${alert.zone ? ` in ${zoneName(alert.zone)}` : ""}`);
        debug.notified = notifier.count;
      },
      onFocus: (alert) => {
        map.focusAlert(alert);
        debug.focused = alert ? alert.id : null;
      },
    },
  );
  await feed.loadAcknowledgements();

  function select(id) {
    selected = debug.selected = id;
    debug.trajectory = 0;
    map.select(id, []);
    people.select(id);
    panel.show(id);
  }

  // --- live streams ---------------------------------------------------------------------------
  let peopleListAt = -Infinity;
  let limits = null; // /api/occupancy: capacities and crowded levels
  let panelSignature = "";
  const trends = new Map(); // zone id -> counts of the last 10 minutes, from the history poll
  /** The occupancy panel and the zone colours from the tick the map draws. */
  function showOccupancy(tracks) {
    if (!limits) return;
    const now = occupancyFromTracks(tracks, limits);
    debug.panelTotal = now.total;
    debug.panelTimeNs = tracks.time_ns;
    const signature = JSON.stringify([now.total, now.zones.map((z) => z.count)]);
    if (signature === panelSignature) return;
    panelSignature = signature;
    renderOccupancy($("occupancy-site"), $("zone-bars"), now, now.crowded_level, trends);
    map.setZoneLevels(now.zones);
  }
  const tracksSocket = new LiveSocket("/ws/tracks", {
    onMessage: (tracks) => {
      latestNs = tracks.time_ns;
      map.setTracks(tracks);
      showOccupancy(tracks);
      feed.setNow(latestNs);
      if (performance.now() - peopleListAt > PEOPLE_LIST_MS) {
        people.update(tracks);
        peopleListAt = performance.now();
      }
      debug.people = tracks.tracks.length;
      debug.violations = tracks.violations.length;
      const pairs = tracks.violations.length;
      $("map-summary").textContent = `${tracks.tracks.length} people · ${pairs ? `${pairs} pair${pairs === 1 ? "" : "s"} too close` : "no one too close"}`;
      $("clock").textContent = clockTime(dateFromNs(latestNs));
    },
    onStatus: socketStatus("tracks"),
  });
  const alertsSocket = new LiveSocket("/ws/alerts?replay=active", {
    onMessage: (alert) => feed.upsert(alert, { fresh: true }),
    onStatus: (status) => {
      socketStatus("alerts")(status);
      if (status.state === "open") catchUpAlerts(); // what happened while the stream was down
    },
  });
  async function catchUpAlerts() {
    try {
      const askedMs = performance.now();
      const [recent, active] = await Promise.all([getJson("/api/alerts?limit=100"), getJson("/api/alerts?active=true&limit=1000")]);
      for (const alert of [...recent.items, ...active.items].reverse()) feed.upsert(alert);
      feed.reconcileActive(active.items.map((a) => a.id), askedMs);
      feed.goLive();
    } catch {
      // the polls report an unreachable gateway; the next reconnect catches up again
    }
  }
  tracksSocket.start();
  alertsSocket.start();

  // --- polls ----------------------------------------------------------------------------------
  const chartLimits = new Map();
  every(
    LIMITS_MS,
    polled(async () => {
      const now = await getJson("/api/occupancy");
      const first = limits === null;
      limits = now;
      if (first) renderOccupancy($("occupancy-site"), $("zone-bars"), now, now.crowded_level); // until the next tick
      chartLimits.set("", { capacity: now.capacity, crowded: now.crowded_level });
      for (const zone of now.zones) chartLimits.set(zone.id, { capacity: zone.capacity, crowded: zone.crowded_level });
      const scope = $("chart-scope").value;
      chart.setScope(scope || null, chartLimits.get(scope) || { capacity: null, crowded: null });
    }),
  );
  every(
    HEALTH_MS,
    polled(async () => {
      const [health, { items: cameras }] = await Promise.all([getJson("/api/health", { alsoOk: [503] }), getJson("/api/cameras?limit=1000")]);
      if (monitor.live) renderStatus($("system-status"), health.status, health.reasons);
      renderDegraded($("degraded-banner"), $("degraded-detail"), health);
      chart.setDegraded(health.degraded_periods);
      debug.degraded = health.reasons.length;
      renderServices($("services"), health);
      renderCameras($("cameras"), cameras);
      map.setCameras(cameras);
    }),
  );
  every(
    HISTORY_MS,
    polled(async () => {
      const [history, intervals] = await Promise.all([
        getJson("/api/occupancy/history?last_s=3600&step_s=10"),
        getJson("/api/intervals?last_s=3600"),
      ]);
      chart.setData(history, intervals.items, latestNs);
      for (const [zone, counts] of Object.entries(history.zones)) trends.set(zone, counts.slice(-60));
      panelSignature = ""; // redraw the panel with the new trends on the next tick
    }),
  );
  setInterval(() => feed.render(), 1000); // "ongoing for ..." durations

  for (const zone of site.zones) $("chart-scope").append(el("option", { value: zone.id }, zone.name || zone.id));
  $("chart-scope").addEventListener("change", (event) => {
    const scope = event.target.value;
    chart.setScope(scope || null, chartLimits.get(scope) || { capacity: null, crowded: null });
  });
  setUpView3d(config.view3d_url);
  const tz = Intl.DateTimeFormat().resolvedOptions().timeZone || "UTC"; // the report's day is the control room's
  for (const link of document.querySelectorAll("#exports [data-report]")) link.href += `&tz=${encodeURIComponent(tz)}`;
  const refreshExports = () => {
    const since = Math.floor(Date.now() / 1000) - 86400;
    for (const link of document.querySelectorAll("#exports [data-csv]")) link.href = `/api/history/${link.dataset.csv}?format=csv&limit=100000&since=${since}`;
  };
  refreshExports();
  setInterval(refreshExports, 60000);
  document.addEventListener("keydown", (event) => event.key === "Escape" && panel.hide());
  debug.ready = true;
  document.body.dataset.ready = "true";
}

function socketStatus(name) {
  return ({ state, attempt, retryInMs }) => {
    if (state === "open") monitor.ok(name);
    else if (state === "closed") {
      monitor.lost(name, `Reconnecting (attempt ${attempt}, next try in ${Math.max(1, Math.round(retryInMs / 1000))} s)…`);
    }
  };
}

function showAttention(feed) {
  const waiting = feed.needingAttention();
  const n = waiting.length;
  debug.alerts = feed.alerts.size;
  debug.attention = n;
  const button = $("attention");
  button.hidden = n === 0;
  $("attention-text").textContent = `${n} alert${n === 1 ? "" : "s"} need${n === 1 ? "s" : ""} attention`;
  button.onclick = () => {
    const first = feed.nodes.get(waiting[0]?.id);
    (first?.querySelector(".ack-button") || $("alerts")).focus();
    first?.scrollIntoView({ block: "nearest" });
  };
  const site = $("site-name").textContent;
  document.title = n ? `(${n}) ${site} · bevflow` : `${site} · bevflow`;
}

function setUpView3d(url) {
  const toggle = $("view3d-toggle");
  const link = $("view3d-link");
  if (!url) {
    toggle.title = "The 3D view is not running on this gateway";
    return;
  }
  link.href = url;
  link.hidden = false;
  toggle.disabled = false;
  toggle.addEventListener("click", () => {
    const panel = $("view3d-panel");
    const frame = $("view3d-frame");
    panel.hidden = !panel.hidden;
    toggle.setAttribute("aria-expanded", String(!panel.hidden));
    toggle.textContent = panel.hidden ? "3D view" : "Floor map";
    if (!panel.hidden && !frame.src) frame.src = url; // loaded on first use only
  });
}

boot();
