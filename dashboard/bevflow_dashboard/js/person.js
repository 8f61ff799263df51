// The side panel for one person: where they are, how long they have been tracked, and who came
// within the social distance of them (/api/tracks/{id} and /api/tracks/{id}/contacts).

import { getJson } from "./api.js";
import { el } from "./dom.js";
import { clockTime, dateFromNs, duration, metres } from "./format.js";

const REFRESH_MS = 2000;

export class PersonPanel {
  /**
   * @param {object} parts  panel, section (shows the panel instead of the people list), title, closeButton, facts, contactsBody, contactsTable, contactsEmpty, contactsLimit
   * @param {object} options  zoneName(id), onTrajectory(id, points), onTrack(id), onClose()
   */
  constructor(parts, { zoneName, onTrajectory, onTrack, onClose }) {
    Object.assign(this, parts);
    this.zoneName = zoneName;
    this.onTrajectory = onTrajectory;
    this.onTrack = onTrack;
    this.onClose = onClose;
    this.trackId = null;
    this.timer = null;
    this.returnFocus = null;
    this.closeButton.addEventListener("click", () => this.hide());
    this.panel.addEventListener("keydown", (event) => event.key === "Escape" && this.hide());
  }

  async show(trackId) {
    if (this.panel.hidden) this.returnFocus = document.activeElement;
    this.trackId = trackId;
    this.panel.hidden = false;
    this.panel.dataset.track = String(trackId);
    this.section.dataset.person = String(trackId);
    this.panel.dataset.loaded = "false";
    this.title.textContent = `Person #${trackId}`;
    this.facts.replaceChildren(el("dt", {}, "Loading…"), el("dd", {}, ""));
    clearTimeout(this.timer);
    this.closeButton.focus({ preventScroll: true });
    await this.refresh();
  }

  hide() {
    if (this.panel.hidden) return;
    clearTimeout(this.timer);
    this.trackId = null;
    this.panel.hidden = true;
    delete this.panel.dataset.track;
    delete this.section.dataset.person;
    this.onClose();
    if (this.returnFocus && document.contains(this.returnFocus)) this.returnFocus.focus({ preventScroll: true });
  }

  async refresh() {
    const trackId = this.trackId;
    if (trackId === null) return;
    try {
      const [detail, contacts] = await Promise.all([
        getJson(`/api/tracks/${trackId}?last_s=900`),
        getJson(`/api/tracks/${trackId}/contacts`),
      ]);
      if (trackId !== this.trackId) return; // another person was opened meanwhile
      this.renderFacts(detail);
      this.renderContacts(contacts);
      this.onTrajectory(trackId, detail.points);
      this.panel.dataset.loaded = "true";
    } catch (error) {
      if (trackId !== this.trackId) return;
      this.facts.replaceChildren(el("dt", {}, "Not available"), el("dd", {}, error.message));
    }
    if (trackId === this.trackId) this.timer = setTimeout(() => this.refresh(), REFRESH_MS);
  }

  renderFacts(detail) {
    const current = detail.current;
    const points = detail.points;
    const rows = [["Status", detail.active ? "tracked now" : "no longer tracked"]];
    if (current) {
      rows.push(["Position", `x ${current.xy[0].toFixed(1)} m, y ${current.xy[1].toFixed(1)} m`]);
      rows.push(["Speed", `${Math.hypot(...current.velocity).toFixed(1)} m/s`]);
      rows.push(["Zone", current.zones.length ? current.zones.map(this.zoneName).join(", ") : "none"]);
      rows.push(["Seen by", current.cameras.length ? current.cameras.join(", ") : "none"]);
    }
    if (points.length) {
      const first = points[0];
      const last = points[points.length - 1];
      let walked = 0;
      for (let i = 1; i < points.length; i++) walked += Math.hypot(points[i].xy[0] - points[i - 1].xy[0], points[i].xy[1] - points[i - 1].xy[1]);
      rows.push(["Since", `${clockTime(dateFromNs(first.time_ns))} (${duration((last.time_ns - first.time_ns) / 1e9)})`]);
      rows.push(["Walked", metres(walked)]);
    }
    this.facts.replaceChildren(...rows.flatMap(([name, value]) => [el("dt", {}, name), el("dd", {}, value)]));
  }

  renderContacts(contacts) {
    this.contactsLimit.textContent = `(closer than ${metres(contacts.limit_m)}, the short ones left out)`;
    const link = (id) =>
      el("button", { type: "button", class: "track-link", "data-track": id, onclick: () => this.onTrack(id) }, `#${id}`);
    // One person the tracker lost and found again under new ids: every id, as one contact.
    const ids = (contact) => (contact.tracks?.length > 1 ? contact.tracks : [contact.track]);
    const rows = contacts.contacts.map((contact) =>
      el(
        "tr",
        { "data-track": contact.track },
        el("td", {}, ...ids(contact).flatMap((id, i) => (i ? [" → ", link(id)] : [link(id)]))),
        el("td", {}, metres(contact.min_distance_m)),
        el("td", {}, duration(contact.duration_s)),
        el("td", {}, clockTime(dateFromNs(contact.first_ns))),
      ),
    );
    this.contactsBody.replaceChildren(...rows);
    this.contactsTable.hidden = rows.length === 0;
    this.contactsEmpty.hidden = rows.length > 0;
  }
}
