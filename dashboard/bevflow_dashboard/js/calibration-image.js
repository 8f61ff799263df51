// The camera's still frame: clicks become pixels of the full-size image (whatever size it is shown
// at), and an overlay draws the marked points and, once a pose is solved, where that pose puts
// each floor point (a green cross, joined to its click by a line as long as the error). A loupe
// beside the pointer magnifies the image, since a large fisheye frame is shown scaled down.

import { cssColor } from "./dom.js";

const LOUPE_PX = 150; // on screen
const LOUPE_ZOOM = 4; // relative to how the image is shown

export class ImageView {
  /** `onClick([u, v])` with a pixel of the full image; `onPick(point)` when a marker is clicked. */
  constructor(img, overlay, { onClick }) {
    this.img = img;
    this.overlay = overlay;
    this.onClick = onClick;
    this.points = [];
    this.selected = null;
    this.solution = null;
    this.hover = null; // client position of the pointer over the image
    img.addEventListener("click", (event) => this.click(event));
    img.addEventListener("mousemove", (event) => {
      this.hover = [event.clientX, event.clientY];
      this.draw();
    });
    img.addEventListener("mouseleave", () => {
      this.hover = null;
      this.draw();
    });
    img.addEventListener("load", () => this.draw());
    new ResizeObserver(() => this.draw()).observe(img);
  }

  /** Show the JPEG at `url`; resolves, once it is shown, to where it came from ("live" or
   * "rendered", the gateway's X-Frame-Source). */
  async load(url) {
    const response = await fetch(url, { cache: "no-store" });
    if (!response.ok) {
      const answer = await response.json().catch(() => ({}));
      throw new Error(answer.detail || `the camera's frame could not be loaded (HTTP ${response.status})`);
    }
    const source = response.headers.get("X-Frame-Source") || "live";
    const blob = await response.blob();
    const previous = this.objectUrl;
    this.objectUrl = URL.createObjectURL(blob);
    await new Promise((resolve, reject) => {
      this.img.onload = resolve;
      this.img.onerror = () => reject(new Error("the camera's frame is not a readable image"));
      this.img.src = this.objectUrl;
    });
    if (previous) URL.revokeObjectURL(previous);
    return source;
  }

  /** Display pixels per image pixel, and the image's top-left corner in client coordinates. */
  scale() {
    const rect = this.img.getBoundingClientRect();
    const natural = this.img.naturalWidth || 1;
    return { factor: rect.width / natural, left: rect.left, top: rect.top, rect };
  }

  click(event) {
    if (!this.img.naturalWidth) return;
    const { factor, left, top } = this.scale();
    const u = (event.clientX - left) / factor;
    const v = (event.clientY - top) / factor;
    if (u < 0 || v < 0 || u > this.img.naturalWidth || v > this.img.naturalHeight) return;
    this.onClick([u, v]);
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

  draw() {
    const { factor, rect } = this.scale();
    const parent = this.overlay.parentElement.getBoundingClientRect();
    const ratio = window.devicePixelRatio || 1;
    Object.assign(this.overlay.style, {
      left: `${rect.left - parent.left}px`,
      top: `${rect.top - parent.top}px`,
      width: `${rect.width}px`,
      height: `${rect.height}px`,
    });
    this.overlay.width = Math.max(1, Math.round(rect.width * ratio));
    this.overlay.height = Math.max(1, Math.round(rect.height * ratio));
    const ctx = this.overlay.getContext("2d");
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    ctx.clearRect(0, 0, rect.width, rect.height);
    if (!this.img.naturalWidth) return;
    const colors = { point: cssColor("--calib-point"), selected: cssColor("--calib-point-selected"), projected: cssColor("--calib-projected") };
    const projected = new Map((this.solution ? this.solution.points : []).map((p) => [p.name, p.projected]));
    ctx.font = "600 12px system-ui, sans-serif";
    ctx.textBaseline = "bottom";
    this.points.forEach((point, index) => {
      const [x, y] = [point.pixel[0] * factor, point.pixel[1] * factor];
      const fitted = projected.get(String(point.id));
      if (fitted) {
        const [fx, fy] = [fitted[0] * factor, fitted[1] * factor];
        ctx.strokeStyle = colors.projected;
        ctx.lineWidth = 1.5;
        ctx.beginPath();
        ctx.moveTo(x, y);
        ctx.lineTo(fx, fy);
        ctx.moveTo(fx - 5, fy - 5);
        ctx.lineTo(fx + 5, fy + 5);
        ctx.moveTo(fx - 5, fy + 5);
        ctx.lineTo(fx + 5, fy - 5);
        ctx.stroke();
      }
      const color = point === this.selected ? colors.selected : colors.point;
      ctx.beginPath();
      ctx.arc(x, y, 5, 0, 2 * Math.PI);
      ctx.lineWidth = 2;
      ctx.strokeStyle = color;
      ctx.stroke();
      ctx.lineWidth = 3;
      ctx.strokeStyle = "#000";
      ctx.strokeText(String(index + 1), x + 7, y - 4);
      ctx.fillStyle = color;
      ctx.fillText(String(index + 1), x + 7, y - 4);
    });
    if (this.hover) this.drawLoupe(ctx, factor, rect);
  }

  /** The image around the pointer, magnified, in a square beside it, with a cross at the pointer. */
  drawLoupe(ctx, factor, rect) {
    const [px, py] = [this.hover[0] - rect.left, this.hover[1] - rect.top];
    const source = LOUPE_PX / (factor * LOUPE_ZOOM); // image pixels across the loupe
    const [u, v] = [px / factor, py / factor];
    const x = px + 20 + LOUPE_PX <= rect.width ? px + 20 : px - 20 - LOUPE_PX;
    const y = Math.max(0, Math.min(py - LOUPE_PX / 2, rect.height - LOUPE_PX));
    ctx.save();
    ctx.imageSmoothingEnabled = false;
    ctx.drawImage(this.img, u - source / 2, v - source / 2, source, source, x, y, LOUPE_PX, LOUPE_PX);
    ctx.strokeStyle = cssColor("--calib-point-selected");
    ctx.lineWidth = 1;
    ctx.strokeRect(x + 0.5, y + 0.5, LOUPE_PX - 1, LOUPE_PX - 1);
    ctx.beginPath();
    ctx.moveTo(x + LOUPE_PX / 2, y + 8);
    ctx.lineTo(x + LOUPE_PX / 2, y + LOUPE_PX - 8);
    ctx.moveTo(x + 8, y + LOUPE_PX / 2);
    ctx.lineTo(x + LOUPE_PX - 8, y + LOUPE_PX / 2);
    ctx.stroke();
    ctx.restore();
  }
}
