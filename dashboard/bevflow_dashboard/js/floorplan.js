// The floor plan under the live layer: floor and metre grid, camera coverage, zones coloured by
// occupancy with their tags, cameras, and the scale bar. Plain functions of a canvas context and a
// View (metres to pixels), so the live map decides only what to draw and when.

import { cssColor, withAlpha } from "./dom.js";
import { niceLengthAtMost, niceStepAtLeast } from "./geometry.js";

/** Floor, metre grid and axis labels. */
export function drawFloor(ctx, view, colors) {
  const [xmin, ymin, xmax, ymax] = view.extent;
  const [left, top] = view.toScreen(xmin, ymax);
  const [right, bottom] = view.toScreen(xmax, ymin);
  ctx.fillStyle = colors.floor;
  ctx.fillRect(left, top, right - left, bottom - top);
  const step = niceStepAtLeast(48, view.scale);
  ctx.strokeStyle = colors.grid;
  ctx.lineWidth = 1;
  ctx.fillStyle = colors.gridLabel;
  ctx.font = "11px system-ui, sans-serif";
  ctx.beginPath();
  for (let x = Math.ceil(xmin / step) * step; x <= xmax + 1e-9; x += step) {
    const [sx] = view.toScreen(x, 0);
    ctx.moveTo(Math.round(sx) + 0.5, top);
    ctx.lineTo(Math.round(sx) + 0.5, bottom);
  }
  for (let y = Math.ceil(ymin / step) * step; y <= ymax + 1e-9; y += step) {
    const [, sy] = view.toScreen(0, y);
    ctx.moveTo(left, Math.round(sy) + 0.5);
    ctx.lineTo(right, Math.round(sy) + 0.5);
  }
  ctx.stroke();
  ctx.textAlign = "center";
  ctx.textBaseline = "top";
  for (let x = Math.ceil(xmin / step) * step; x <= xmax + 1e-9; x += step) ctx.fillText(label(x), view.toScreen(x, 0)[0], bottom + 4);
  ctx.textAlign = "right";
  ctx.textBaseline = "middle";
  for (let y = Math.ceil(ymin / step) * step; y <= ymax + 1e-9; y += step) ctx.fillText(label(y), left - 5, view.toScreen(0, y)[1]);
  ctx.strokeStyle = colors.gridEdge;
  ctx.strokeRect(left + 0.5, top + 0.5, right - left - 1, bottom - top - 1);
}

/** Each camera's monitored circle, clipped to the floor. */
export function drawCoverage(ctx, view, colors, cameras) {
  ctx.save();
  const [xmin, ymin, xmax, ymax] = view.extent;
  const [left, top] = view.toScreen(xmin, ymax);
  const [right, bottom] = view.toScreen(xmax, ymin);
  ctx.beginPath();
  ctx.rect(left, top, right - left, bottom - top);
  ctx.clip(); // coverage beyond the floor means nothing
  ctx.setLineDash([5, 5]);
  ctx.lineWidth = 1;
  for (const camera of cameras) {
    if (!camera.monitored_radius_m) continue;
    const [x, y] = view.toScreen(camera.position[0], camera.position[1]);
    ctx.beginPath();
    ctx.arc(x, y, camera.monitored_radius_m * view.scale, 0, 2 * Math.PI);
    ctx.fillStyle = withAlpha(colors.coverage, 0.035);
    ctx.fill();
    ctx.strokeStyle = withAlpha(colors.coverage, 0.35);
    ctx.stroke();
  }
  ctx.restore();
}

/** Zones filled and outlined in the colour of their occupancy level. */
export function drawZones(ctx, view, colors, zones, levels) {
  for (const zone of zones) {
    const now = levels.get(zone.id);
    const level = now ? now.level : "unknown";
    const color = colors.levels[level] || colors.levels.unknown;
    ctx.beginPath();
    zone.polygon.forEach(([x, y], i) => ctx[i ? "lineTo" : "moveTo"](...view.toScreen(x, y)));
    ctx.closePath();
    ctx.fillStyle = withAlpha(color, level === "over_capacity" ? 0.3 : 0.18);
    ctx.fill();
    ctx.lineWidth = level === "over_capacity" ? 2.5 : 1.5;
    ctx.strokeStyle = color;
    ctx.stroke();
  }
}

/** Each zone's name and count on a tag above its top-left corner, over the people. */
export function drawZoneTags(ctx, view, colors, zones, levels, width) {
  ctx.font = "600 12px system-ui, sans-serif";
  ctx.textAlign = "left";
  ctx.textBaseline = "middle";
  for (const zone of zones) {
    const now = levels.get(zone.id);
    const color = colors.levels[now ? now.level : "unknown"] || colors.levels.unknown;
    const corners = zone.polygon.map(([x, y]) => view.toScreen(x, y));
    const left = Math.min(...corners.map((c) => c[0]));
    const top = Math.min(...corners.map((c) => c[1]));
    const text = `${zone.name || zone.id}  ${now ? now.count : "–"}${now && now.capacity !== null ? ` / ${now.capacity}` : ""}`;
    const w = ctx.measureText(text).width + 12;
    const h = 18;
    const x = Math.max(2, Math.min(left, width - w - 2));
    const y = top - h - 3 >= 2 ? top - h - 3 : top + 3;
    ctx.fillStyle = color;
    roundedRect(ctx, x, y, w, h, 4);
    ctx.fill();
    ctx.fillStyle = colors.floor;
    ctx.fillText(text, x + 6, y + h / 2 + 0.5);
  }
}

/** Cameras as triangles, red when down, with their ids. */
export function drawCameras(ctx, view, colors, cameras) {
  ctx.font = "11px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.textBaseline = "bottom";
  for (const camera of cameras) {
    const [x, y] = view.toScreen(camera.position[0], camera.position[1]);
    const color = camera.state === "down" ? colors.levels.over_capacity : camera.state === "up" ? colors.camera : colors.levels.unknown;
    ctx.beginPath();
    ctx.moveTo(x, y - 7);
    ctx.lineTo(x + 6.5, y + 5);
    ctx.lineTo(x - 6.5, y + 5);
    ctx.closePath();
    ctx.fillStyle = color;
    ctx.fill();
    ctx.lineWidth = 1.5;
    ctx.strokeStyle = colors.floor;
    ctx.stroke();
    outlinedText(ctx, camera.state === "down" ? `${camera.id} (down)` : camera.id, x, y - 9, color, colors.floor);
  }
}

/** A scale bar in the floor's bottom-left corner, where the axis labels leave it room. */
export function drawScaleBar(ctx, view, colors) {
  const length = niceLengthAtMost(140, view.scale);
  const pixels = length * view.scale;
  const [left, bottom] = view.toScreen(view.extent[0], view.extent[1]);
  const x = left + 14;
  const y = bottom - 12;
  // No box behind it: a zone in that corner stays visible; a halo keeps the bar readable on it.
  for (const [color, width] of [[colors.floor, 5], [colors.text, 2]]) {
    ctx.strokeStyle = color;
    ctx.lineWidth = width;
    ctx.beginPath();
    ctx.moveTo(x, y - 5);
    ctx.lineTo(x, y);
    ctx.lineTo(x + pixels, y);
    ctx.lineTo(x + pixels, y - 5);
    ctx.stroke();
  }
  ctx.font = "600 11px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.textBaseline = "bottom";
  outlinedText(ctx, `${label(length)} m`, x + pixels / 2, y - 4, colors.text, colors.floor);
}

/** A one-line warning across the top of the map. */
export function drawNotice(ctx, colors, width, text) {
  ctx.font = "600 13px system-ui, sans-serif";
  const w = ctx.measureText(text).width + 24;
  ctx.fillStyle = withAlpha(colors.floor, 0.92);
  ctx.fillRect((width - w) / 2, 10, w, 28);
  ctx.strokeStyle = colors.levels.crowded;
  ctx.strokeRect((width - w) / 2 + 0.5, 10.5, w - 1, 27);
  ctx.fillStyle = colors.levels.crowded;
  ctx.textAlign = "center";
  ctx.textBaseline = "middle";
  ctx.fillText(text, width / 2, 24);
}

/** The map's colours, from the stylesheet's custom properties. */
export function palette() {
  return {
    floor: cssColor("--map-floor"),
    grid: cssColor("--map-grid"),
    gridEdge: cssColor("--border"),
    gridLabel: cssColor("--map-grid-label"),
    text: cssColor("--text"),
    person: cssColor("--map-person"),
    personEdge: cssColor("--map-person-edge"),
    trail: cssColor("--map-trail"),
    violation: cssColor("--map-violation"),
    camera: cssColor("--map-camera"),
    coverage: cssColor("--map-coverage"),
    selected: cssColor("--map-selected"),
    levels: {
      normal: cssColor("--level-normal"),
      crowded: cssColor("--level-crowded"),
      over_capacity: cssColor("--level-over"),
      unknown: cssColor("--level-unknown"),
    },
  };
}

/** A metre value as a short label: 5, 2.5. */
function label(value) {
  return Number.isInteger(value) ? String(value) : value.toFixed(1);
}

function roundedRect(ctx, x, y, w, h, r) {
  ctx.beginPath();
  ctx.moveTo(x + r, y);
  ctx.arcTo(x + w, y, x + w, y + h, r);
  ctx.arcTo(x + w, y + h, x, y + h, r);
  ctx.arcTo(x, y + h, x, y, r);
  ctx.arcTo(x, y, x + w, y, r);
  ctx.closePath();
}

/** Text with a dark outline, legible over lines and dots. */
export function outlinedText(ctx, text, x, y, fill, outline) {
  ctx.lineWidth = 3;
  ctx.strokeStyle = outline;
  ctx.lineJoin = "round";
  ctx.strokeText(text, x, y);
  ctx.fillStyle = fill;
  ctx.fillText(text, x, y);
}
