// Service and camera health badges, from /api/health and /api/cameras.

import { el } from "./dom.js";
import { duration } from "./format.js";

const STATUS_TEXT = { ok: "all systems ok", degraded: "degraded", stale: "no fresh data", no_data: "no data yet", down: "gateway unreachable" };

/** The header pill: the gateway's overall status (or "down" when it cannot be reached), and why. */
export function renderStatus(pill, status, reasons = []) {
  pill.dataset.status = status;
  pill.textContent = STATUS_TEXT[status] || status;
  pill.title = reasons.length ? `Degraded: ${reasons.join("; ")}` : "Gateway health";
}

/** The warning under the top bar while the live data is incomplete or late (/api/health reasons). */
export function renderDegraded(banner, detail, health) {
  const reasons = health.reasons || [];
  banner.hidden = reasons.length === 0;
  detail.textContent = reasons.join("; ");
  banner.title = reasons.join("\n");
}

function badge(name, state, detail) {
  return el(
    "li",
    { class: "badge", "data-state": state, title: detail || undefined },
    el("span", {}, name),
    el("span", { class: "badge-state" }, state),
  );
}

/** Services: every live one (from liveliness tokens), plus the gateway answering this page. */
export function renderServices(list, health) {
  const counts = new Map();
  for (const service of health.services) counts.set(service.name, (counts.get(service.name) || 0) + 1);
  const badges = [badge("gateway", "up", `up for ${duration(health.uptime_s)}`)];
  for (const [name, n] of [...counts].sort()) {
    if (name !== "gateway") badges.push(badge(n > 1 ? `${name} ×${n}` : name, "up"));
  }
  const tracker = health.tracks_age_s === null ? "no tracks yet" : `last tracks ${health.tracks_age_s.toFixed(1)} s ago`;
  badges.push(badge("tracks", health.status === "stale" || health.status === "no_data" ? "down" : "up", tracker));
  list.replaceChildren(...badges);
}

export function renderCameras(list, cameras) {
  list.replaceChildren(
    ...cameras.map((camera) => {
      const detail =
        camera.state === "up"
          ? `${camera.frames_received} frames, ${camera.frames_dropped} dropped`
          : camera.reason || camera.state;
      const node = badge(camera.id, camera.state, detail);
      node.dataset.camera = camera.id;
      return node;
    }),
  );
}
