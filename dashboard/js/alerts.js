// The alert feed: alerts by id, newest first, updated in place as they start and end.
//
// Each alert keeps one list item for its whole life, so a keyboard user's focus on its buttons is
// not lost when the feed refreshes.

import { acknowledgeAlert, loadAcknowledgements } from "./acknowledge.js";
import { el } from "./dom.js";
import { alertLabel, alertSeverity, clockTime, dateFromNs, duration, metres } from "./format.js";

const MAX_ALERTS = 200; // ended alerts beyond this are dropped from the feed, oldest first
// "camera_up" is a moment, not a condition: it ends the camera's open "camera_down" alerts.
const MOMENTARY = new Set(["camera_up"]);

export class AlertFeed {
  /**
   * @param {object} parts  list, empty, count, announcer (a live region for screen readers), showEnded (checkbox)
   * @param {object} options  site (id), zoneName(id), onTrack(trackId), onChange(feed)
   */
  constructor(parts, { site, zoneName, onTrack, onChange = () => {} }) {
    Object.assign(this, parts);
    this.site = site;
    this.zoneName = zoneName;
    this.onTrack = onTrack;
    this.onChange = onChange;
    this.alerts = new Map();
    this.nodes = new Map();
    this.acknowledged = new Map();
    this.nowNs = null;
    this.showEnded.addEventListener("change", () => this.render());
  }

  async loadAcknowledgements() {
    this.acknowledged = await loadAcknowledgements(this.site);
    this.render();
  }

  /** Take one AlertMessage (from the websocket or REST); `fresh` marks a newly arrived one. */
  upsert(alert, { fresh = false } = {}) {
    const known = this.alerts.get(alert.id);
    if (known && known.end_ns !== null && alert.end_ns === null) return; // an end is final
    const isNew = fresh && !known && alert.active && !MOMENTARY.has(alert.type);
    this.alerts.set(alert.id, { ...alert, isNew, receivedMs: performance.now() });
    if (isNew) this.announcer.textContent = `New alert: ${alertLabel(alert.type)}${alert.zone ? `, ${this.zoneName(alert.zone)}` : ""}`;
    if (alert.type === "camera_up") this.endCameraDown(alert);
    this.prune();
    this.render();
  }

  /**
   * After a reconnect: `activeIds` are the alerts the gateway lists as ongoing, as of a request sent
   * at `askedMs` (performance.now()). An alert we hold as ongoing that it no longer knows (it was
   * restarted, and its memory went with it) is shown as "no longer reported" rather than ongoing.
   */
  reconcileActive(activeIds, askedMs) {
    const known = new Set(activeIds);
    for (const [id, alert] of this.alerts) {
      if (alert.active && !known.has(id) && alert.receivedMs < askedMs && !MOMENTARY.has(alert.type)) {
        this.alerts.set(id, { ...alert, active: false, unreported: true });
      }
    }
    this.render();
  }

  endCameraDown(up) {
    for (const [id, other] of this.alerts) {
      if (other.type === "camera_down" && other.active && other.event.camera === up.event.camera && other.start_ns <= up.start_ns) {
        this.alerts.set(id, { ...other, active: false, end: up.start, end_ns: up.start_ns });
      }
    }
  }

  prune() {
    if (this.alerts.size <= MAX_ALERTS) return;
    const ended = this.sorted().filter((a) => !a.active).reverse();
    for (const alert of ended.slice(0, this.alerts.size - MAX_ALERTS)) this.alerts.delete(alert.id);
  }

  /** Capture time of the newest data, for "ongoing for 45 s". */
  setNow(nowNs) {
    this.nowNs = nowNs;
  }

  async acknowledge(alertId) {
    const record = await acknowledgeAlert(this.site, alertId);
    this.acknowledged.set(alertId, record);
    this.render();
  }

  isActive(alert) {
    return alert.active && !MOMENTARY.has(alert.type);
  }

  /** Alerts that are still going on and nobody has acknowledged. */
  needingAttention() {
    return this.sorted().filter((a) => this.isActive(a) && !this.acknowledged.has(a.id));
  }

  sorted() {
    return [...this.alerts.values()].sort((a, b) => b.start_ns - a.start_ns || (a.id < b.id ? 1 : -1));
  }

  render() {
    const alerts = this.sorted();
    const showEnded = this.showEnded.checked;
    for (const [id, node] of this.nodes) {
      if (!this.alerts.has(id)) {
        node.remove();
        this.nodes.delete(id);
      }
    }
    let previous = null;
    let shown = 0;
    for (const alert of alerts) {
      let node = this.nodes.get(alert.id);
      if (!node) {
        node = el("li", { class: "alert", tabindex: "-1" });
        this.nodes.set(alert.id, node);
      }
      this.update(node, alert);
      node.hidden = !showEnded && !this.isActive(alert);
      shown += node.hidden ? 0 : 1;
      const wanted = previous ? previous.nextSibling : this.list.firstChild;
      if (wanted !== node) this.list.insertBefore(node, wanted);
      previous = node;
    }
    const attention = this.needingAttention().length;
    this.count.textContent = String(attention);
    this.count.dataset.count = String(attention);
    this.count.setAttribute("aria-label", `${attention} active alerts not acknowledged`);
    this.empty.hidden = shown > 0;
    this.empty.textContent = alerts.length ? "No ongoing alerts." : "No alerts.";
    this.onChange(this);
  }

  update(node, alert) {
    const acknowledged = this.acknowledged.get(alert.id);
    const active = this.isActive(alert);
    const signature = JSON.stringify([alert.end_ns, active, Boolean(acknowledged), Boolean(alert.unreported)]);
    node.dataset.id = alert.id;
    node.dataset.type = alert.type;
    node.dataset.active = String(active);
    node.dataset.acknowledged = String(Boolean(acknowledged));
    node.dataset.severity = alertSeverity(alert.type);
    node.classList.toggle("is-new", Boolean(alert.isNew));
    if (node.dataset.signature !== signature) {
      node.dataset.signature = signature;
      node.replaceChildren(this.head(alert), this.body(alert), this.foot(alert, active, acknowledged));
    } else {
      node.querySelector(".alert-state").textContent = this.stateText(alert, active);
    }
  }

  head(alert) {
    const zone = alert.zone ? this.zoneName(alert.zone) : null;
    const start = dateFromNs(alert.start_ns);
    return el(
      "div",
      { class: "alert-head" },
      el("span", { class: "alert-type" }, alertLabel(alert.type)),
      zone ? el("span", { class: "alert-zone" }, zone) : null,
      el("time", { class: "alert-time", datetime: alert.start }, clockTime(start)),
    );
  }

  body(alert) {
    const event = alert.event || {};
    const tracks = alert.tracks.map((id) => el("button", { type: "button", class: "track-link", onclick: () => this.onTrack(id) }, `#${id}`));
    const joined = tracks.flatMap((button, i) => (i ? [i === tracks.length - 1 ? " and " : ", ", button] : [button]));
    let detail;
    switch (alert.type) {
      case "distance_violation":
        detail = ["People ", ...joined, ` ${metres(event.min_distance_m)} apart (limit ${metres(event.limit_m)})`];
        break;
      case "over_capacity":
        detail = [`Peak ${event.peak} people, capacity ${event.capacity}`];
        break;
      case "camera_down":
        detail = [`Camera ${event.camera}${event.reason ? `: ${event.reason}` : ""}`];
        break;
      case "camera_up":
        detail = [`Camera ${event.camera} is sending frames again`];
        break;
      case "calibration_drift":
        detail = [`Camera ${event.camera} shifted ${metres(event.shift_m)}${event.reference_camera ? ` against ${event.reference_camera}` : ""}`];
        break;
      default:
        detail = tracks.length ? ["People ", ...joined] : [];
    }
    if (alert.type !== "distance_violation" && tracks.length) detail.push(" · people ", ...joined);
    return el("div", { class: "alert-body" }, ...detail);
  }

  stateText(alert, active) {
    const nowNs = this.nowNs ?? Date.now() * 1e6;
    if (MOMENTARY.has(alert.type)) return "event";
    if (active) return `ongoing · ${duration((nowNs - alert.start_ns) / 1e9)}`;
    if (alert.unreported) return "no longer reported by the gateway";
    return `ended ${clockTime(dateFromNs(alert.end_ns))} · lasted ${duration((alert.end_ns - alert.start_ns) / 1e9)}`;
  }

  foot(alert, active, acknowledged) {
    const state = el("span", { class: "alert-state" }, this.stateText(alert, active));
    if (acknowledged) {
      return el("div", { class: "alert-foot" }, state, el("span", { class: "ack-note" }, `✓ acknowledged ${clockTime(new Date(acknowledged.at))}`));
    }
    const label = `Acknowledge ${alertLabel(alert.type)}${alert.zone ? ` in ${this.zoneName(alert.zone)}` : ""} at ${clockTime(dateFromNs(alert.start_ns))}`;
    const button = el("button", { type: "button", class: "button ack-button", "aria-label": label }, "Acknowledge");
    button.addEventListener("click", async () => {
      button.disabled = true;
      const node = this.nodes.get(alert.id);
      try {
        await this.acknowledge(alert.id);
        node?.focus({ preventScroll: true }); // the button is gone; keep the keyboard user's place
      } catch {
        button.disabled = false; // not recorded: let the operator try again
      }
    });
    return el("div", { class: "alert-foot" }, state, button);
  }
}
