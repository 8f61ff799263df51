// The floor plan of the calibration page: zones, cameras and the selected camera's coverage
// circle, the floor points typed so far, and the solved camera position. A click gives the floor
// position under the cursor, rounded to 5 cm.

import { cssColor } from "./dom.js";
import { drawCameras, drawCoverage, drawFloor, drawScaleBar, drawZones, outlinedText, palette } from "./floorplan.js";
import { View } from "./geometry.js";

const SNAP_M = 0.05;

function snap(value) {
  return Math.round(value / SNAP_M) * SNAP_M;
}

export class PlanView {
  /** `onClick(x, y)` with a floor position in metres; `onMove(x, y)` while the pointer is over it. */
  constructor(canvas, { onClick, onMove = () => {} }) {
    this.canvas = canvas;
    this.onClick = onClick;
    this.onMove = onMove;
    this.site = null;
    this.camera = null;
    this.points = [];
    this.selected = null;
    this.solution = null;
    this.view = null;
    canvas.addEventListener("click", (event) => this.click(event));
    canvas.addEventListener("mousemove", (event) => {
      const at = this.worldAt(event);
      if (at) this.onMove(...at);
    });
    new ResizeObserver(() => this.draw()).observe(canvas.parentElement);
  }

  /** The /api/calibration overview, and the id of the camera being calibrated. */
  setSite(site, cameraId) {
    this.site = site;
    this.camera = cameraId;
    this.draw();
  }

  setPoints(points, selected) {
    this.points = points;
    this.selected = selected;
    this.draw();
  }

  setSolution(solution) {
    this.solution = solution;
    this.draw();
  }

  worldAt(event) {
    if (!this.view) return null;
    const rect = this.canvas.getBoundingClientRect();
    const [x, y] = this.view.toWorld(event.clientX - rect.left, event.clientY - rect.top);
    return [Number(snap(x).toFixed(2)), Number(snap(y).toFixed(2))];
  }

  click(event) {
    const at = this.worldAt(event);
    if (at) this.onClick(...at);
  }

  draw() {
    const rect = this.canvas.parentElement.getBoundingClientRect();
    const ratio = window.devicePixelRatio || 1;
    this.canvas.width = Math.max(1, Math.round(rect.width * ratio));
    this.canvas.height = Math.max(1, Math.round(rect.height * ratio));
    const ctx = this.canvas.getContext("2d");
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    ctx.clearRect(0, 0, rect.width, rect.height);
    if (!this.site) return;
    const colors = palette();
    this.view = new View(this.site.floor, rect.width, rect.height);
    const view = this.view;
    drawFloor(ctx, view, colors);
    drawZones(ctx, view, colors, this.site.zones.map((polygon, k) => ({ id: `zone-${k}`, polygon })), new Map());
    // The coverage circle of the camera being calibrated: where it hangs now, and how far it sees.
    const mine = this.site.cameras.filter((c) => c.id === this.camera).map((c) => ({ ...c, monitored_radius_m: c.coverage_radius_m }));
    drawCoverage(ctx, view, colors, mine);
    drawCameras(ctx, view, colors, this.site.cameras.map((c) => ({ ...c, state: c.id === this.camera ? "up" : "unknown" })));
    if (this.solution) this.drawSolved(ctx, view, colors);
    this.drawPoints(ctx, view, colors);
    drawScaleBar(ctx, view, colors);
  }

  drawSolved(ctx, view, colors) {
    const [x, y] = view.toScreen(this.solution.position[0], this.solution.position[1]);
    ctx.strokeStyle = cssColor("--calib-projected");
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.arc(x, y, 7, 0, 2 * Math.PI);
    ctx.stroke();
    ctx.font = "11px system-ui, sans-serif";
    ctx.textAlign = "left";
    ctx.textBaseline = "middle";
    outlinedText(ctx, "solved", x + 10, y, cssColor("--calib-projected"), colors.floor);
  }

  drawPoints(ctx, view, colors) {
    ctx.font = "600 12px system-ui, sans-serif";
    ctx.textAlign = "left";
    ctx.textBaseline = "bottom";
    this.points.forEach((point, index) => {
      if (point.world[0] === null || point.world[1] === null) return;
      const [x, y] = view.toScreen(point.world[0], point.world[1]);
      const color = point === this.selected ? cssColor("--calib-point-selected") : cssColor("--calib-point");
      ctx.beginPath();
      ctx.arc(x, y, 4.5, 0, 2 * Math.PI);
      ctx.fillStyle = color;
      ctx.fill();
      outlinedText(ctx, String(index + 1), x + 6, y - 3, color, colors.floor);
    });
  }
}
