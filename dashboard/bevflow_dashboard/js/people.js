// The list of people tracked now: the keyboard's way to the same person panel as a click on the map.

import { el } from "./dom.js";

export class PeopleList {
  constructor(list, countNode, { zoneName, onSelect }) {
    this.list = list;
    this.countNode = countNode;
    this.zoneName = zoneName;
    this.onSelect = onSelect;
    this.buttons = new Map(); // track id -> button, kept so focus survives updates
    this.selected = null;
  }

  update(tracks) {
    const violating = new Set(tracks.violations.flat());
    const people = [...tracks.tracks].sort((a, b) => a.id - b.id);
    const present = new Set(people.map((p) => p.id));
    for (const [id, button] of this.buttons) {
      if (!present.has(id)) {
        button.parentElement.remove();
        this.buttons.delete(id);
      }
    }
    let previous = null;
    for (const person of people) {
      let button = this.buttons.get(person.id);
      if (!button) {
        button = el("button", { type: "button", class: "person-button", onclick: () => this.onSelect(person.id) });
        this.buttons.set(person.id, button);
        el("li", {}, button);
      }
      const zone = person.zones.length ? this.zoneName(person.zones[0]) : "";
      if (button.dataset.zone !== zone || !button.firstChild) {
        button.dataset.zone = zone;
        button.replaceChildren(el("span", { class: "person-id" }, `#${person.id}`), el("span", { class: "person-zone" }, zone));
      }
      button.dataset.track = String(person.id);
      button.dataset.violating = String(violating.has(person.id));
      button.setAttribute("aria-pressed", String(person.id === this.selected));
      const close = violating.has(person.id) ? ", too close to someone" : "";
      button.setAttribute("aria-label", `Person ${person.id}${zone ? `, ${zone}` : ""}${close}`);
      const item = button.parentElement;
      const wanted = previous ? previous.nextSibling : this.list.firstChild;
      if (wanted !== item) this.list.insertBefore(item, wanted);
      previous = item;
    }
    this.countNode.textContent = String(people.length);
  }

  select(id) {
    this.selected = id;
    for (const [trackId, button] of this.buttons) button.setAttribute("aria-pressed", String(trackId === id));
  }
}
