// The live floor map: zones coloured by occupancy, cameras and their coverage, people with short
// trails, red lines between people too close together, and the selected person's trajectory.
// Drawn on a canvas in metres, north (+Y) up; redrawn only when something changed.

import { incidentPeople } from "./alert-detail.js";
import { withAlpha } from "./dom.js";
import { drawCameras, drawCoverage, drawFloor, drawNotice, drawScaleBar, drawZoneTags, drawZones, outlinedText, palette } from "./floorplan.js";
import { View, floorExtent } from "./geometry.js";

const TRAIL_S = 4; // seconds of trail behind each person
const TRAIL_MIN_STEP_S = 0.25; // at most four trail points a second, whatever the tick rate
const PICK_RADIUS_PX = 14; // how far from a dot a click still picks it
const STALE_AFTER_MS = 3000; // no tick for this long: people are drawn dimmed

export class FloorMap {
  constructor(canvas, { onSelect }) {
    this.canvas = canvas;
    this.onSelect = onSelect;
    this.site = { zones: [] };
    this.cameras = [];
    this.levels = new Map(); // zone id -> {level, count, capacity}
    this.people = []; // TrackState of the latest tick
    this.violations = [];
    this.trails = new Map(); // track id -> [[t_s, x, y], ...]
    this.tickWallMs = 0;
    this.selected = null;
    this.focus = null; // the alert clicked in the feed: {id, xy, people: Set, zone}
    this.trajectory = [];
    this.hover = null;
    this.view = null;
    this.drawn = []; // the people as the last frame showed them: what a click refers to
    this.pending = false;
    new ResizeObserver(() => this.invalidate()).observe(canvas.parentElement);
    canvas.addEventListener("click", (event) => this.click(event));
    canvas.addEventListener("mousemove", (event) => this.move(event));
    canvas.addEventListener("mouseleave", () => this.setHover(null));
    setInterval(() => this.isStale() && this.invalidate(), 1000);
  }

  setSite(site) {
    this.site = site;
    this.invalidate();
  }

  setCameras(cameras) {
    this.cameras = cameras;
    this.invalidate();
  }

  setZoneLevels(zones) {
    this.levels = new Map(zones.map((z) => [z.id, z]));
    this.invalidate();
  }

  /** One Tracks message from /ws/tracks. */
  setTracks(tracks) {
    const t = tracks.time_ns / 1e9;
    const present = new Set();
    for (const person of tracks.tracks) {
      present.add(person.id);
      const trail = this.trails.get(person.id) || [];
      const last = trail[trail.length - 1];
      if (!last || t - last[0] >= TRAIL_MIN_STEP_S) trail.push([t, person.xy[0], person.xy[1]]);
      else trail[trail.length - 1] = [last[0], person.xy[0], person.xy[1]];
      while (trail.length && trail[0][0] < t - TRAIL_S) trail.shift();
      this.trails.set(person.id, trail);
    }
    for (const id of this.trails.keys()) if (!present.has(id)) this.trails.delete(id);
    this.people = tracks.tracks;
    this.violations = tracks.violations;
    this.tickWallMs = performance.now();
    this.canvas.dataset.people = String(this.people.length);
    this.canvas.dataset.violations = String(this.violations.length);
    this.canvas.setAttribute("aria-label", `Floor map: ${this.people.length} people, ${this.violations.length} pairs too close`);
    this.invalidate();
  }

  /** Highlight person `id` (or nobody) and draw `points` (TrajectoryPoint list) as their path. */
  select(id, points = []) {
    this.selected = id;
    this.trajectory = points;
    this.invalidate();
  }

  /** Show an alert from the feed (or nothing, with null): its place ringed, its people marked. */
  focusAlert(alert) {
    const event = alert?.event || {};
    this.focus = alert && {
      id: alert.id,
      xy: event.position || null,
      people: new Set(alert.type === "distance_incident" ? incidentPeople(alert) : alert.tracks),
      zone: alert.zone,
      camera: event.camera || null,
    };
    this.canvas.dataset.focus = alert ? alert.id : "";
    this.invalidate();
  }

  /** Where person `id` is drawn now (as of the last frame), in page pixels; null if not drawn. */
  screenOf(id) {
    const person = this.drawn.find((p) => p.id === id);
    if (!person || !this.view) return null;
    const [x, y] = this.view.toScreen(person.xy[0], person.xy[1]);
    const box = this.canvas.getBoundingClientRect();
    return { x: box.left + x, y: box.top + y };
  }

  isStale() {
    return this.people.length > 0 && performance.now() - this.tickWallMs > STALE_AFTER_MS;
  }

  pick(event) {
    if (!this.view) return null;
    const box = this.canvas.getBoundingClientRect();
    const px = event.clientX - box.left;
    const py = event.clientY - box.top;
    let best = null;
    let bestDistance = PICK_RADIUS_PX;
    for (const person of this.drawn) {
      const [x, y] = this.view.toScreen(person.xy[0], person.xy[1]);
      const distance = Math.hypot(x - px, y - py);
      if (distance <= bestDistance) [best, bestDistance] = [person.id, distance];
    }
    return best;
  }

  click(event) {
    const id = this.pick(event);
    if (id !== null) this.onSelect(id);
  }

  move(event) {
    this.setHover(this.pick(event));
  }

  setHover(id) {
    if (id === this.hover) return;
    this.hover = id;
    this.canvas.style.cursor = id === null ? "default" : "pointer";
    this.invalidate();
  }

  invalidate() {
    if (this.pending) return;
    this.pending = true;
    requestAnimationFrame(() => {
      this.pending = false;
      this.draw();
    });
  }

  draw() {
    const canvas = this.canvas;
    const ratio = window.devicePixelRatio || 1;
    const width = canvas.clientWidth;
    const height = canvas.clientHeight;
    if (!width || !height) return;
    if (canvas.width !== Math.round(width * ratio) || canvas.height !== Math.round(height * ratio)) {
      canvas.width = Math.round(width * ratio);
      canvas.height = Math.round(height * ratio);
    }
    const ctx = canvas.getContext("2d");
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    ctx.clearRect(0, 0, width, height);
    const extent = floorExtent(this.site, this.cameras);
    this.view = new View(extent, width, height, 28);
    // Where the layout sizes the map by its content (narrow screens), it follows the floor's shape.
    canvas.parentElement.style.setProperty("--floor-aspect", ((extent[2] - extent[0]) / (extent[3] - extent[1]) + 0.1).toFixed(3));
    const colors = palette();
    const view = this.view;
    const zones = this.site.zones || [];
    drawFloor(ctx, view, colors);
    drawCoverage(ctx, view, colors, this.cameras);
    drawZones(ctx, view, colors, zones, this.levels);
    this.drawTrajectory(ctx, colors);
    ctx.globalAlpha = this.isStale() ? 0.35 : 1;
    this.drawTrails(ctx, colors);
    this.drawViolations(ctx, colors);
    this.drawPeople(ctx, colors);
    this.drawFocus(ctx, colors, zones);
    this.drawn = this.people;
    ctx.globalAlpha = 1;
    drawZoneTags(ctx, view, colors, zones, this.levels, width);
    drawCameras(ctx, view, colors, this.cameras);
    drawScaleBar(ctx, view, colors);
    if (this.isStale()) drawNotice(ctx, colors, width, "No live positions: the last update is a few seconds old");
  }





  /** The focused alert: a ring around its people (or its zone, or its camera), and their ids. */
  drawFocus(ctx, colors, zones) {
    const focus = this.focus;
    if (!focus) return;
    const members = this.people.filter((p) => focus.people.has(p.id));
    this.canvas.dataset.focusPeople = members.map((p) => p.id).join(",");
    ctx.save();
    ctx.strokeStyle = colors.selected;
    ctx.lineWidth = 2.5;
    ctx.setLineDash([6, 4]);
    const camera = focus.camera && this.cameras.find((c) => c.id === focus.camera);
    const points = members.length ? members.map((p) => p.xy) : focus.xy ? [focus.xy] : camera?.position ? [camera.position] : [];
    if (points.length) {
      const cx = points.reduce((a, p) => a + p[0], 0) / points.length;
      const cy = points.reduce((a, p) => a + p[1], 0) / points.length;
      const spread = Math.max(1.5, ...points.map((p) => Math.hypot(p[0] - cx, p[1] - cy) + 1));
      const [x, y] = this.view.toScreen(cx, cy);
      ctx.beginPath();
      ctx.arc(x, y, spread * this.view.scale, 0, 2 * Math.PI);
      ctx.stroke();
    } else {
      const zone = zones.find((z) => z.id === focus.zone);
      if (zone) {
        ctx.beginPath();
        zone.polygon.forEach(([zx, zy], i) => ctx[i ? "lineTo" : "moveTo"](...this.view.toScreen(zx, zy)));
        ctx.closePath();
        ctx.stroke();
      }
    }
    ctx.setLineDash([]);
    ctx.font = "700 12px system-ui, sans-serif";
    ctx.textAlign = "left";
    ctx.textBaseline = "bottom";
    for (const person of members) {
      const [x, y] = this.view.toScreen(person.xy[0], person.xy[1]);
      ctx.beginPath();
      ctx.arc(x, y, 11, 0, 2 * Math.PI);
      ctx.stroke();
      outlinedText(ctx, `#${person.id}`, x + 12, y - 8, colors.text, colors.floor);
    }
    ctx.restore();
  }

  drawTrajectory(ctx, colors) {
    if (this.selected === null || this.trajectory.length < 1) return;
    const points = this.trajectory.map((p) => this.view.toScreen(p.xy[0], p.xy[1]));
    ctx.save();
    ctx.strokeStyle = withAlpha(colors.selected, 0.85);
    ctx.lineWidth = 2;
    ctx.lineJoin = "round";
    ctx.beginPath();
    points.forEach(([x, y], i) => ctx[i ? "lineTo" : "moveTo"](x, y));
    ctx.stroke();
    ctx.fillStyle = colors.selected;
    for (const [x, y] of points) ctx.fillRect(x - 1.5, y - 1.5, 3, 3);
    const [sx, sy] = points[0];
    ctx.beginPath();
    ctx.arc(sx, sy, 5, 0, 2 * Math.PI);
    ctx.lineWidth = 2;
    ctx.stroke();
    ctx.font = "600 11px system-ui, sans-serif";
    ctx.textAlign = "left";
    ctx.textBaseline = "middle";
    outlinedText(ctx, "start", sx + 8, sy, colors.selected, colors.floor);
    ctx.restore();
  }

  drawTrails(ctx, colors) {
    ctx.lineWidth = 2;
    ctx.lineCap = "round";
    for (const person of this.people) {
      const trail = this.trails.get(person.id);
      if (!trail || trail.length < 2) continue;
      const newest = trail[trail.length - 1][0];
      for (let i = 1; i < trail.length; i++) {
        const age = newest - trail[i][0];
        ctx.strokeStyle = withAlpha(colors.trail, 0.55 * (1 - age / TRAIL_S));
        ctx.beginPath();
        ctx.moveTo(...this.view.toScreen(trail[i - 1][1], trail[i - 1][2]));
        ctx.lineTo(...this.view.toScreen(trail[i][1], trail[i][2]));
        ctx.stroke();
      }
    }
  }

  drawViolations(ctx, colors) {
    const byId = new Map(this.people.map((p) => [p.id, p]));
    ctx.strokeStyle = colors.violation;
    ctx.lineWidth = 2.5;
    ctx.beginPath();
    for (const [a, b] of this.violations) {
      const pa = byId.get(a);
      const pb = byId.get(b);
      if (!pa || !pb) continue;
      ctx.moveTo(...this.view.toScreen(pa.xy[0], pa.xy[1]));
      ctx.lineTo(...this.view.toScreen(pb.xy[0], pb.xy[1]));
    }
    ctx.stroke();
  }

  drawPeople(ctx, colors) {
    const violating = new Set(this.violations.flat());
    for (const person of this.people) {
      const [x, y] = this.view.toScreen(person.xy[0], person.xy[1]);
      const r = Math.max(4, Math.min(9, (person.radius || 0.3) * this.view.scale * 0.8));
      ctx.beginPath();
      ctx.arc(x, y, r, 0, 2 * Math.PI);
      ctx.fillStyle = violating.has(person.id) ? colors.violation : colors.person;
      ctx.fill();
      ctx.lineWidth = 1.5;
      ctx.strokeStyle = colors.personEdge;
      ctx.stroke();
      if (person.id === this.selected || person.id === this.hover) {
        ctx.beginPath();
        ctx.arc(x, y, r + 4, 0, 2 * Math.PI);
        ctx.lineWidth = 2.5;
        ctx.strokeStyle = person.id === this.selected ? colors.selected : colors.text;
        ctx.stroke();
        ctx.font = "700 12px system-ui, sans-serif";
        ctx.textAlign = "left";
        ctx.textBaseline = "bottom";
        outlinedText(ctx, `#${person.id}`, x + r + 4, y - r - 2, colors.text, colors.floor);
      }
    }
  }



}
