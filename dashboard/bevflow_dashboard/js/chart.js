// The last hour of occupancy for the whole site or one zone, with its crowded intervals shaded and
// its capacity and crowded level drawn as lines.

import { cssColor, withAlpha } from "./dom.js";
import { dateFromNs, shortTime } from "./format.js";

const WINDOW_S = 3600;
const NS = 1e9;

export class OccupancyChart {
  constructor(canvas) {
    this.canvas = canvas;
    this.history = null; // OccupancyHistory
    this.intervals = []; // CrowdedIntervalView list
    this.degraded = []; // /api/health degraded_periods: when the counts were not to be trusted
    this.scope = null; // zone id, or null for the whole site
    this.limits = { capacity: null, crowded: null };
    this.nowNs = null;
    new ResizeObserver(() => this.draw()).observe(canvas.parentElement);
  }

  /** New data: `history` from /api/occupancy/history, `intervals` from /api/intervals. */
  setData(history, intervals, nowNs) {
    this.history = history;
    this.intervals = intervals;
    this.nowNs = nowNs;
    this.draw();
  }

  /** Periods of degraded data (/api/health), hatched so that a dip there does not read as people leaving. */
  setDegraded(periods) {
    this.degraded = periods || [];
    this.canvas.dataset.degraded = String(this.degraded.length);
    this.draw();
  }

  /** Which series to show (zone id or null) and its capacity and crowded level. */
  setScope(scope, limits) {
    this.scope = scope;
    this.limits = limits;
    this.draw();
  }

  series() {
    if (!this.history) return { times: [], counts: [] };
    const counts = this.scope === null ? this.history.total : this.history.zones[this.scope] || [];
    return { times: this.history.time_ns, counts };
  }

  draw() {
    const canvas = this.canvas;
    const ratio = window.devicePixelRatio || 1;
    const width = canvas.clientWidth;
    const height = canvas.clientHeight;
    if (!width || !height) return;
    canvas.width = Math.round(width * ratio);
    canvas.height = Math.round(height * ratio);
    const ctx = canvas.getContext("2d");
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    ctx.clearRect(0, 0, width, height);

    const { times, counts } = this.series();
    const endNs = this.nowNs ?? (times.length ? times[times.length - 1] : Date.now() * 1e6);
    const startNs = endNs - WINDOW_S * NS;
    const top = Math.max(5, ...counts, this.limits.capacity ?? 0, this.limits.crowded ?? 0) * 1.1;
    const box = { left: 38, right: width - 12, top: 10, bottom: height - 24 };
    const x = (ns) => box.left + ((ns - startNs) / (endNs - startNs)) * (box.right - box.left);
    const y = (count) => box.bottom - (count / top) * (box.bottom - box.top);
    const colors = {
      grid: cssColor("--map-grid"),
      label: cssColor("--muted"),
      line: cssColor("--chart-line"),
      band: cssColor("--chart-band"),
      over: cssColor("--level-over"),
      crowded: cssColor("--level-crowded"),
    };

    this.drawBands(ctx, colors, x, box, startNs, endNs);
    this.drawDegraded(ctx, colors, x, box, startNs, endNs);
    this.drawAxes(ctx, colors, x, y, box, top, startNs, endNs);
    this.drawLimit(ctx, this.limits.capacity, colors.over, "capacity", y, box);
    this.drawLimit(ctx, this.limits.crowded, colors.crowded, "crowded", y, box);
    this.drawLine(ctx, colors, times, counts, x, y, box, startNs);
    if (!counts.length) {
      ctx.fillStyle = colors.label;
      ctx.font = "13px system-ui, sans-serif";
      ctx.textAlign = "center";
      ctx.textBaseline = "middle";
      ctx.fillText("No occupancy recorded yet", (box.left + box.right) / 2, (box.top + box.bottom) / 2);
    }
  }

  drawBands(ctx, colors, x, box, startNs, endNs) {
    ctx.fillStyle = withAlpha(colors.band, 0.22);
    for (const interval of this.intervals) {
      if ((interval.zone ?? null) !== this.scope) continue;
      const from = Math.max(startNs, interval.start_ns);
      const to = Math.min(endNs, interval.end_ns ?? endNs);
      if (to <= from) continue;
      ctx.fillRect(x(from), box.top, Math.max(2, x(to) - x(from)), box.bottom - box.top);
    }
  }

  drawDegraded(ctx, colors, x, box, startNs, endNs) {
    ctx.save();
    ctx.strokeStyle = withAlpha(colors.label, 0.45);
    ctx.lineWidth = 1;
    for (const period of this.degraded) {
      const from = Math.max(startNs, period.start_ns);
      const to = Math.min(endNs, period.end_ns ?? endNs);
      if (to <= from) continue;
      const [left, right] = [x(from), Math.max(x(from) + 3, x(to))];
      ctx.beginPath();
      ctx.rect(left, box.top, right - left, box.bottom - box.top);
      ctx.clip();
      ctx.beginPath();
      for (let px = left - (box.bottom - box.top); px < right; px += 6) {
        ctx.moveTo(px, box.bottom);
        ctx.lineTo(px + (box.bottom - box.top), box.top);
      }
      ctx.stroke();
      ctx.restore();
      ctx.save();
      ctx.strokeStyle = withAlpha(colors.label, 0.45);
    }
    ctx.restore();
  }

  drawAxes(ctx, colors, x, y, box, top, startNs, endNs) {
    ctx.strokeStyle = colors.grid;
    ctx.fillStyle = colors.label;
    ctx.lineWidth = 1;
    ctx.font = "11px system-ui, sans-serif";
    const step = [1, 2, 5, 10, 20, 50, 100, 200, 500, 1000].find((s) => top / s <= 5) ?? 1000;
    ctx.textAlign = "right";
    ctx.textBaseline = "middle";
    for (let v = 0; v <= top; v += step) {
      const py = Math.round(y(v)) + 0.5;
      ctx.beginPath();
      ctx.moveTo(box.left, py);
      ctx.lineTo(box.right, py);
      ctx.stroke();
      ctx.fillText(String(v), box.left - 6, py);
    }
    ctx.textAlign = "center";
    ctx.textBaseline = "top";
    const tick = 10 * 60 * NS;
    for (let t = Math.ceil(startNs / tick) * tick; t <= endNs; t += tick) {
      const px = Math.round(x(t)) + 0.5;
      ctx.beginPath();
      ctx.moveTo(px, box.bottom);
      ctx.lineTo(px, box.bottom + 4);
      ctx.stroke();
      ctx.fillText(shortTime(dateFromNs(t)), px, box.bottom + 6);
    }
  }

  drawLimit(ctx, value, color, text, y, box) {
    if (value === null || value === undefined) return;
    const py = Math.round(y(value)) + 0.5;
    ctx.save();
    ctx.setLineDash([6, 4]);
    ctx.strokeStyle = color;
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    ctx.moveTo(box.left, py);
    ctx.lineTo(box.right, py);
    ctx.stroke();
    ctx.restore();
    ctx.fillStyle = color;
    ctx.font = "600 11px system-ui, sans-serif";
    ctx.textAlign = "right";
    ctx.textBaseline = "bottom";
    ctx.fillText(`${text} ${value}`, box.right - 2, py - 2);
  }

  drawLine(ctx, colors, times, counts, x, y, box, startNs) {
    const points = [];
    for (let i = 0; i < times.length; i++) if (times[i] >= startNs) points.push([x(times[i]), y(counts[i])]);
    if (!points.length) return;
    const gradient = ctx.createLinearGradient(0, box.top, 0, box.bottom);
    gradient.addColorStop(0, withAlpha(colors.line, 0.3));
    gradient.addColorStop(1, withAlpha(colors.line, 0.02));
    ctx.beginPath();
    ctx.moveTo(points[0][0], box.bottom);
    for (const [px, py] of points) ctx.lineTo(px, py);
    ctx.lineTo(points[points.length - 1][0], box.bottom);
    ctx.closePath();
    ctx.fillStyle = gradient;
    ctx.fill();
    ctx.beginPath();
    points.forEach(([px, py], i) => ctx[i ? "lineTo" : "moveTo"](px, py));
    ctx.strokeStyle = colors.line;
    ctx.lineWidth = 2;
    ctx.lineJoin = "round";
    ctx.stroke();
    const [lx, ly] = points[points.length - 1];
    ctx.beginPath();
    ctx.arc(lx, ly, 3.5, 0, 2 * Math.PI);
    ctx.fillStyle = colors.line;
    ctx.fill();
  }
}
