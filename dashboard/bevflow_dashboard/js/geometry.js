// Metres on the floor to pixels on a canvas, and the "nice" steps used for grids and scale bars.

const NICE_STEPS = [0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100, 200, 500, 1000];

/** The floor area to show: the site's `floor`, or everything the cameras and zones cover. */
export function floorExtent(site, cameras) {
  if (site.floor) return site.floor;
  const xs = [];
  const ys = [];
  for (const camera of cameras) {
    const r = camera.monitored_radius_m || 0;
    xs.push(camera.position[0] - r, camera.position[0] + r);
    ys.push(camera.position[1] - r, camera.position[1] + r);
  }
  for (const zone of site.zones || []) {
    for (const [x, y] of zone.polygon) {
      xs.push(x);
      ys.push(y);
    }
  }
  if (!xs.length) return [-10, -10, 10, 10];
  const pad = 1;
  return [Math.min(...xs) - pad, Math.min(...ys) - pad, Math.max(...xs) + pad, Math.max(...ys) + pad];
}

/** Fits `extent` (xmin, ymin, xmax, ymax in metres) into a `width` × `height` pixel box, north up,
 * `padding` pixels from each edge. */
export class View {
  constructor(extent, width, height, padding = 24) {
    const [xmin, ymin, xmax, ymax] = extent;
    this.extent = extent;
    this.scale = Math.max(1e-6, Math.min((width - 2 * padding) / (xmax - xmin), (height - 2 * padding) / (ymax - ymin)));
    this.left = (width - (xmax - xmin) * this.scale) / 2;
    this.top = (height - (ymax - ymin) * this.scale) / 2;
  }

  /** Pixel position of world point (x, y); +Y points up the screen. */
  toScreen(x, y) {
    const [xmin, , , ymax] = this.extent;
    return [this.left + (x - xmin) * this.scale, this.top + (ymax - y) * this.scale];
  }

  toWorld(px, py) {
    const [xmin, , , ymax] = this.extent;
    return [xmin + (px - this.left) / this.scale, ymax - (py - this.top) / this.scale];
  }
}

/** The smallest nice step (1, 2, 5 × 10^k metres) at least `minPixels` long at `scale` px/m. */
export function niceStepAtLeast(minPixels, scale) {
  return NICE_STEPS.find((step) => step * scale >= minPixels) ?? NICE_STEPS[NICE_STEPS.length - 1];
}

/** The largest nice length at most `maxPixels` long at `scale` px/m (for a scale bar). */
export function niceLengthAtMost(maxPixels, scale) {
  const fitting = NICE_STEPS.filter((step) => step * scale <= maxPixels);
  return fitting.length ? fitting[fitting.length - 1] : NICE_STEPS[0];
}
