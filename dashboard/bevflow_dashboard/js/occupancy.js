// "Occupancy now": the site's count against its capacity, and one bar per zone.
//
// The counts come from the same Tracks message the map draws (each person carries its zones), so
// the map and this panel always show the same tick; capacities and crowded levels come from
// /api/occupancy.

import { el } from "./dom.js";

const LEVEL_TEXT = { crowded: "crowded", over_capacity: "over capacity" };

function bar(count, capacity, crowdedLevel, level) {
  const full = Math.max(capacity ?? 0, count, 1);
  const fill = el("span", { class: "bar-fill" });
  fill.style.width = `${Math.min(100, (100 * count) / full)}%`;
  const node = el("span", { class: "bar", "data-level": level, "aria-hidden": "true" }, fill);
  if (crowdedLevel !== null && crowdedLevel !== undefined && crowdedLevel < full) {
    const mark = el("span", { class: "bar-mark", title: `crowded from ${crowdedLevel}` });
    mark.style.left = `${(100 * crowdedLevel) / full}%`;
    node.append(mark);
  }
  return node;
}

function levelTag(level) {
  return LEVEL_TEXT[level] ? el("span", { class: "level-tag", "data-level": level }, LEVEL_TEXT[level]) : null;
}

function ofCapacity(count, capacity) {
  return capacity === null || capacity === undefined ? String(count) : `${count} / ${capacity}`;
}

/** The level of a count, by the rule of the gateway's /api/occupancy (``routes/occupancy.level_of``). */
function levelOf(count, crowded, capacity) {
  if (capacity !== null && capacity !== undefined && count > capacity) return "over_capacity";
  if (crowded !== null && crowded !== undefined && count >= crowded) return "crowded";
  return (capacity ?? crowded ?? null) === null ? "unknown" : "normal";
}

/** An /api/occupancy-shaped view of one Tracks message, with the limits of `limits` (/api/occupancy). */
export function occupancyFromTracks(tracks, limits) {
  const counts = new Map();
  for (const person of tracks.tracks) for (const zone of person.zones) counts.set(zone, (counts.get(zone) || 0) + 1);
  const total = tracks.tracks.length;
  return {
    time_ns: tracks.time_ns,
    total,
    capacity: limits.capacity,
    crowded_level: limits.crowded_level,
    level: levelOf(total, limits.crowded_level, limits.capacity),
    zones: limits.zones.map((z) => {
      const count = counts.get(z.id) || 0;
      return { ...z, count, level: levelOf(count, z.crowded_level, z.capacity) };
    }),
  };
}

const SVG = "http://www.w3.org/2000/svg";

/** A small line of the last minutes of a zone's counts (an SVG with presentation attributes only). */
function sparkline(values) {
  const svg = document.createElementNS(SVG, "svg");
  svg.setAttribute("class", "sparkline");
  svg.setAttribute("viewBox", "0 0 100 20");
  svg.setAttribute("preserveAspectRatio", "none");
  svg.setAttribute("aria-hidden", "true");
  if (values.length > 1) {
    const top = Math.max(1, ...values);
    const points = values.map((v, i) => `${((100 * i) / (values.length - 1)).toFixed(1)},${(19 - (18 * v) / top).toFixed(1)}`);
    const line = document.createElementNS(SVG, "polyline");
    line.setAttribute("points", points.join(" "));
    line.setAttribute("fill", "none");
    line.setAttribute("stroke", "currentColor");
    line.setAttribute("stroke-width", "1.5");
    line.setAttribute("vector-effect", "non-scaling-stroke");
    svg.append(line);
  }
  return svg;
}

/** Render an /api/occupancy-shaped view into the site line and the zone list; `trends` maps a zone
 * id to its recent counts (oldest first) for a sparkline beside its count. */
export function renderOccupancy(siteNode, zonesNode, now, crowdedLevelOfSite, trends = new Map()) {
  const parts = [
    el("span", { class: "big-count", "aria-label": `${now.total} people on site` }, String(now.total)),
    el("span", { class: "muted" }, now.capacity !== null ? `of ${now.capacity}` : "people"),
    bar(now.total, now.capacity, crowdedLevelOfSite, now.level),
    levelTag(now.level),
  ];
  siteNode.replaceChildren(...parts.filter(Boolean));
  siteNode.dataset.level = now.level;
  zonesNode.replaceChildren(
    ...now.zones.map((zone) =>
      el(
        "li",
        { class: "zone-bar", "data-zone": zone.id, "data-level": zone.level },
        el(
          "div",
          { class: "zone-line" },
          el("span", { class: "zone-name" }, zone.name || zone.id),
          levelTag(zone.level),
          trends.has(zone.id) ? sparkline(trends.get(zone.id)) : null,
          el("span", { class: "zone-count", "aria-label": `${zone.count} people, capacity ${zone.capacity ?? "not set"}` }, ofCapacity(zone.count, zone.capacity)),
        ),
        bar(zone.count, zone.capacity, zone.crowded_level, zone.level),
      ),
    ),
  );
}
