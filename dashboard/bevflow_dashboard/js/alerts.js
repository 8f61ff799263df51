// The alert feed: alerts by id, newest first, updated in place as they start, change and end.
//
// Each alert keeps one list item for its whole life, so a keyboard user's focus on its buttons is
// not lost when the feed refreshes. Each alert gets its place once, when first seen: the alerts
// found when the page loads by their start, newest first; those arriving live after that on top
// (an incident starts before it is raised, so its start would put it below others). Nothing is
// ever re-sorted; while the pointer or the keyboard focus is in the list, nothing is added, removed or
// hidden there (new alerts wait, counted above the list), so what is under the cursor stays put.

import { acknowledgeAlert, acknowledgeAlerts, loadAcknowledgements } from "./acknowledge.js";
import { alertDetail, wantsAcknowledgement } from "./alert-detail.js";
import { el } from "./dom.js";
import { alertLabel, alertSeverity, clockTime, dateFromNs, duration } from "./format.js";

const MAX_ALERTS = 200; // ended alerts beyond this are dropped from the feed, oldest first
// "camera_up" is a moment, not a condition: it ends the camera's open "camera_down" alerts.
const MOMENTARY = new Set(["camera_up"]);

export class AlertFeed {
  /**
   * @param {object} parts  list, empty, count, announcer (a live region for screen readers), showEnded (checkbox),
   *   held (the "n new" line shown while the feed holds still), ackAll (button)
   * @param {object} options  site (id), zoneName(id), onTrack(trackId), onFocus(alert or null), onChange(feed),
   *   onArrive(alert): an alert that just arrived live or changed
   */
  constructor(parts, { site, zoneName, onTrack, onFocus = () => {}, onChange = () => {}, onArrive = () => {} }) {
    Object.assign(this, parts);
    this.site = site;
    this.zoneName = zoneName;
    this.onTrack = onTrack;
    this.onFocus = onFocus;
    this.onChange = onChange;
    this.onArrive = onArrive;
    this.alerts = new Map();
    this.nodes = new Map();
    this.acknowledged = new Map();
    this.nowNs = null;
    this.nextSeq = 0;
    this.topKey = -Infinity;
    this.live = false; // set once the alerts of before the page loaded are in
    this.focused = null;
    this.pointerIn = false;
    this.showEnded.addEventListener("change", () => this.render());
    this.list.addEventListener("pointerenter", () => (this.pointerIn = true));
    this.list.addEventListener("pointerleave", () => {
      this.pointerIn = false;
      this.render();
    });
    this.list.addEventListener("focusout", () => setTimeout(() => this.render()));
    this.ackAll?.addEventListener("click", () => this.acknowledgeAll());
  }

  /** Whether the list must hold still: the pointer is over it, or a control in it has the focus. */
  holding() {
    return this.pointerIn || this.list.contains(document.activeElement);
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
    const seq = known ? known.seq : this.nextSeq++;
    const key = known ? known.key : this.live ? Math.max(alert.start_ns, this.topKey) : alert.start_ns;
    this.topKey = Math.max(this.topKey, key);
    this.alerts.set(alert.id, { ...alert, isNew: isNew || Boolean(known?.isNew), seq, key, receivedMs: performance.now() });
    if (isNew) this.announcer.textContent = `New alert: ${alertLabel(alert.type)}${alert.zone ? `, ${this.zoneName(alert.zone)}` : ""}`;
    if (alert.type === "camera_up") this.endCameraDown(alert);
    if (fresh) this.onArrive(this.alerts.get(alert.id));
    this.prune();
    this.render();
  }

  /** From now on, alerts not seen before go on top. */
  goLive() {
    this.live = true;
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

  async acknowledge(alertId, note = "") {
    const record = await acknowledgeAlert(this.site, alertId, note);
    this.acknowledged.set(alertId, record);
    this.render();
  }

  /** Acknowledge every alert that needs attention, in one request. */
  async acknowledgeAll() {
    const ids = this.needingAttention().map((a) => a.id);
    if (!ids.length) return;
    this.ackAll.disabled = true;
    try {
      for (const [id, record] of await acknowledgeAlerts(this.site, ids)) this.acknowledged.set(id, record);
    } finally {
      this.ackAll.disabled = false;
      this.render();
    }
  }

  /** Show alert `id` on the map (or nothing, with null); a second click on the same one clears it. */
  focus(id) {
    this.focused = id === this.focused ? null : id;
    for (const [nodeId, node] of this.nodes) node.dataset.focused = String(nodeId === this.focused);
    this.onFocus(this.focused === null ? null : this.alerts.get(this.focused) || null);
  }

  isActive(alert) {
    return alert.active && !MOMENTARY.has(alert.type);
  }

  /** Alerts that are still going on and nobody has acknowledged. */
  needingAttention() {
    return this.sorted().filter((a) => this.isActive(a) && !this.acknowledged.has(a.id));
  }

  /** Newest first by the place each alert got when first seen (above); it keeps it for life. */
  sorted() {
    return [...this.alerts.values()].sort((a, b) => b.key - a.key || b.seq - a.seq);
  }

  render() {
    const alerts = this.sorted();
    const hold = this.holding();
    let waiting = 0;
    let shown = 0;
    if (!hold) this.removeGone();
    let previous = null;
    for (const alert of alerts) {
      let node = this.nodes.get(alert.id);
      if (!node && hold) {
        waiting += 1;
        continue;
      }
      if (!node) {
        node = el("li", { class: "alert", tabindex: "-1", "data-focused": "false" });
        node.addEventListener("click", (event) => event.target.closest("button, input, a") || this.focus(alert.id));
        this.nodes.set(alert.id, node);
      }
      this.update(node, this.alerts.get(alert.id));
      if (!hold) {
        node.hidden = !this.showEnded.checked && !this.isActive(alert);
        const wanted = previous ? previous.nextSibling : this.list.firstChild;
        if (wanted !== node) this.list.insertBefore(node, wanted);
        previous = node;
      }
      shown += node.hidden ? 0 : 1;
    }
    if (this.held) {
      this.held.hidden = waiting === 0;
      this.held.textContent = `${waiting} new alert${waiting === 1 ? "" : "s"} above; they appear when the pointer leaves the list`;
    }
    const attention = this.needingAttention().length;
    this.count.textContent = String(attention);
    this.count.dataset.count = String(attention);
    this.count.setAttribute("aria-label", `${attention} active alerts not acknowledged`);
    this.empty.hidden = shown > 0;
    this.empty.textContent = alerts.length ? "No ongoing alerts." : "No alerts.";
    if (this.ackAll) this.ackAll.hidden = attention < 2;
    this.onChange(this);
  }

  removeGone() {
    for (const [id, node] of this.nodes) {
      if (!this.alerts.has(id)) {
        node.remove();
        this.nodes.delete(id);
      }
    }
  }

  update(node, alert) {
    const acknowledged = this.acknowledged.get(alert.id);
    const active = this.isActive(alert);
    const signature = JSON.stringify([alert.end_ns, active, Boolean(acknowledged), Boolean(alert.unreported), alert.tracks, alert.event?.current]);
    node.dataset.id = alert.id;
    node.dataset.type = alert.type;
    node.dataset.active = String(active);
    node.dataset.acknowledged = String(Boolean(acknowledged));
    node.dataset.severity = alertSeverity(alert.type);
    node.dataset.attention = String(active && !acknowledged);
    node.classList.toggle("is-new", Boolean(alert.isNew));
    if (node.dataset.signature !== signature) {
      node.dataset.signature = signature;
      const note = node.querySelector(".ack-input");
      node.replaceChildren(this.head(alert), this.body(alert), this.foot(alert, active, acknowledged));
      const input = node.querySelector(".ack-input");
      if (note && input) input.value = note.value; // a note being typed survives the update
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
    return el("div", { class: "alert-body" }, ...alertDetail(alert, this.onTrack));
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
      const note = acknowledged.note ? ` · “${acknowledged.note}”` : "";
      return el("div", { class: "alert-foot" }, state, el("span", { class: "ack-note" }, `✓ acknowledged ${clockTime(new Date(acknowledged.at))}${note}`));
    }
    if (!active && !wantsAcknowledgement(alert)) {
      return el("div", { class: "alert-foot" }, state, el("span", { class: "ack-note" }, "short and over: no action needed"));
    }
    const label = `Acknowledge ${alertLabel(alert.type)}${alert.zone ? ` in ${this.zoneName(alert.zone)}` : ""} at ${clockTime(dateFromNs(alert.start_ns))}`;
    const input = el("input", { type: "text", class: "ack-input", maxlength: "1000", placeholder: "note (optional)", "aria-label": `Note for: ${label}` });
    const button = el("button", { type: "button", class: "button ack-button", "aria-label": label }, "Acknowledge");
    button.addEventListener("click", async () => {
      button.disabled = true;
      const node = this.nodes.get(alert.id);
      try {
        await this.acknowledge(alert.id, input.value.trim());
        node?.focus({ preventScroll: true }); // the button is gone; keep the keyboard user's place
      } catch {
        button.disabled = false; // not recorded: let the operator try again
      }
    });
    return el("div", { class: "alert-foot" }, state, input, button);
  }
}
