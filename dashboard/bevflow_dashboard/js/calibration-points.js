// The calibration points: each a pixel clicked in the camera's image and the floor position typed
// (or clicked on the plan) for it, shown as a table with each point's error once a pose is solved.

import { el } from "./dom.js";

let nextId = 1;

/** One point; `world` holds [x, y, z] in metres, with null where nothing was entered yet. */
function makePoint(pixel) {
  return { id: nextId++, pixel, world: [null, null, 0], error: null };
}

export class PointList {
  /** `onChange(points)` after any edit; `onSelect(point)` when a row or marker is chosen. */
  constructor(body, { onChange, onSelect }) {
    this.body = body;
    this.onChange = onChange;
    this.onSelect = onSelect;
    this.points = [];
    this.selected = null;
  }

  add(pixel) {
    const point = makePoint(pixel);
    this.points.push(point);
    this.select(point);
    this.changed();
    const x = this.body.querySelector(`tr[data-id="${point.id}"] input[name="x"]`);
    if (x) x.focus();
    return point;
  }

  remove(point) {
    this.points = this.points.filter((p) => p !== point);
    if (this.selected === point) this.selected = this.points[this.points.length - 1] || null;
    this.changed();
  }

  clear() {
    this.points = [];
    this.selected = null;
    this.changed();
  }

  select(point) {
    this.selected = point;
    this.render();
    this.onSelect(point);
  }

  /** The floor position clicked on the plan goes to the selected point (z kept). */
  setFloor(x, y) {
    if (!this.selected) return;
    this.selected.world[0] = x;
    this.selected.world[1] = y;
    this.changed();
  }

  /** Move the selected point's pixel by (du, dv) image pixels: finer than a click on a scaled image. */
  nudge(du, dv) {
    if (!this.selected) return;
    this.selected.pixel = [this.selected.pixel[0] + du, this.selected.pixel[1] + dv];
    this.changed();
  }

  /** Points with a pixel and a full floor position, as the API takes them. */
  complete() {
    return this.points
      .filter((p) => p.world.every((v) => v !== null && Number.isFinite(v)))
      .map((p) => ({ name: String(p.id), pixel: p.pixel, world: p.world }));
  }

  /** Per-point errors from a solution (matched by name), or none. */
  setErrors(solution) {
    const byName = new Map((solution ? solution.points : []).map((p) => [p.name, p]));
    for (const point of this.points) point.error = byName.get(String(point.id)) || null;
    this.render();
  }

  changed() {
    for (const point of this.points) point.error = null;
    this.render();
    this.onChange(this.points);
  }

  render() {
    const focused = document.activeElement;
    const keep = focused && focused.closest && focused.closest("tr") ? [focused.closest("tr").dataset.id, focused.name] : null;
    this.body.replaceChildren(...this.points.map((p, k) => this.row(p, k)));
    if (keep) {
      const again = this.body.querySelector(`tr[data-id="${keep[0]}"] input[name="${keep[1]}"]`);
      if (again) again.focus();
    }
  }

  row(point, index) {
    const input = (axis, k) =>
      el("input", {
        name: axis,
        type: "number",
        step: "any",
        inputmode: "decimal",
        "aria-label": `point ${index + 1} ${axis} in metres`,
        value: point.world[k] === null ? "" : String(point.world[k]),
        onchange: (event) => this.typed(point, k, event.target.value),
        onfocus: () => this.selected !== point && this.selectQuietly(point),
      });
    const error = point.error;
    const px = error && error.reprojection_px !== null ? error.reprojection_px : null;
    const metres = error && error.ground_error_m !== null ? error.ground_error_m : null;
    return el(
      "tr",
      { "data-id": point.id, "data-index": index, "aria-selected": this.selected === point ? "true" : "false" },
      el("td", {}, el("span", { class: "point-id", onclick: () => this.select(point), title: "select" }, index + 1)),
      el("td", {}, point.pixel[0].toFixed(1)),
      el("td", {}, point.pixel[1].toFixed(1)),
      el("td", {}, input("x", 0)),
      el("td", {}, input("y", 1)),
      el("td", {}, input("z", 2)),
      el("td", { class: px !== null && px > 3 ? "error-px error-bad" : "error-px" }, px === null ? "–" : px.toFixed(2)),
      el("td", { class: metres !== null && metres > 0.15 ? "error-m error-bad" : "error-m" }, metres === null ? "–" : metres.toFixed(3)),
      el("td", {}, el("button", { type: "button", class: "button button-quiet", "aria-label": `remove point ${index + 1}`, onclick: () => this.remove(point) }, "✕")),
    );
  }

  /** Select without re-rendering the table, so the focused input keeps its caret. */
  selectQuietly(point) {
    this.selected = point;
    for (const tr of this.body.querySelectorAll("tr")) tr.setAttribute("aria-selected", tr.dataset.id === String(point.id) ? "true" : "false");
    this.onSelect(point);
  }

  typed(point, k, text) {
    const value = text.trim() === "" ? (k === 2 ? 0 : null) : Number(text);
    point.world[k] = Number.isFinite(value) ? value : null;
    this.changed();
  }
}
