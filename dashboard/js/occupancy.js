// "Occupancy now": the site's count against its capacity, and one bar per zone.

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

/** Render /api/occupancy into the site line and the zone list. */
export function renderOccupancy(siteNode, zonesNode, now, crowdedLevelOfSite) {
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
          el("span", { class: "zone-count", "aria-label": `${zone.count} people, capacity ${zone.capacity ?? "not set"}` }, ofCapacity(zone.count, zone.capacity)),
        ),
        bar(zone.count, zone.capacity, zone.crowded_level, zone.level),
      ),
    ),
  );
}
