// The installer's calibration page: pick a camera, click points in its still frame, give each
// its floor position, preview the solved pose with every point's error, and save it into the
// site file. `window.calibration` exposes the page's state to tests and to the console.

import { ApiError, getJson } from "./api.js";
import { el } from "./dom.js";
import { refreshChecks } from "./calibration-checks.js";
import { ImageView } from "./calibration-image.js";
import { PlanView } from "./calibration-plan.js";
import { PointList } from "./calibration-points.js";

const MIN_POINTS = 4; // what a pose needs at all; the overview says how many make it checkable
const PREVIEW_DELAY_MS = 300;
const CHECKS_EVERY_MS = 5000;

const $ = (id) => document.getElementById(id);
const page = (window.calibration = { ready: false, camera: null, solution: null, saved: null, error: null, points: () => points.points });

/** PUT or POST `body` as JSON; the parsed answer, or ApiError with the gateway's message. */
async function sendJson(method, path, body) {
  let response;
  try {
    response = await fetch(path, { method, headers: { "Content-Type": "application/json", Accept: "application/json" }, body: JSON.stringify(body) });
  } catch {
    throw new ApiError(`${path}: unreachable`);
  }
  const answer = await response.json().catch(() => ({}));
  if (!response.ok) {
    const detail = typeof answer.detail === "string" ? answer.detail : answer.message || `HTTP ${response.status}`;
    throw new ApiError(detail);
  }
  return answer;
}

function status(text, kind = "") {
  const node = $("status");
  node.textContent = text;
  node.dataset.kind = kind;
}

const image = new ImageView($("frame"), $("image-overlay"), { onClick: (pixel) => points.add(pixel) });
const plan = new PlanView($("plan"), {
  onClick: (x, y) => points.setFloor(x, y),
  onMove: (x, y) => ($("plan-cursor").textContent = `x ${x.toFixed(2)} m, y ${y.toFixed(2)} m`),
});
const points = new PointList($("points-body"), {
  onChange: () => pointsChanged(),
  onSelect: (point) => {
    image.setPoints(points.points, point);
    plan.setPoints(points.points, point);
  },
});

let overview = null;
let previewTimer = null;
let previewSeq = 0;

function pointsChanged() {
  const all = points.points;
  const ready = points.complete();
  $("points-count").textContent = `${all.length} point${all.length === 1 ? "" : "s"}, ${ready.length} with a floor position`;
  $("points-empty").hidden = all.length > 0;
  $("clear").disabled = all.length === 0;
  $("preview").disabled = ready.length < MIN_POINTS;
  setSolution(null);
  image.setPoints(all, points.selected);
  plan.setPoints(all, points.selected);
  clearTimeout(previewTimer);
  if (ready.length >= MIN_POINTS) previewTimer = setTimeout(preview, PREVIEW_DELAY_MS);
  else status(ready.length ? `${MIN_POINTS - ready.length} more point(s) with a floor position needed for a pose` : "");
}

function setSolution(solution) {
  page.solution = solution;
  image.setSolution(solution);
  plan.setSolution(solution);
  points.setErrors(solution);
  $("save").disabled = !(solution && solution.accepted && overview && overview.editable);
  const box = $("solution");
  if (!solution) {
    box.replaceChildren();
    return;
  }
  const [x, y, z] = solution.position;
  box.replaceChildren(
    el("div", {}, `RMS reprojection error ${solution.rms_px === null ? "–" : solution.rms_px.toFixed(2)} px, RMS ground error ${solution.rms_ground_m === null ? "–" : solution.rms_ground_m.toFixed(3)} m`),
    el("div", {}, `camera at (${x.toFixed(2)}, ${y.toFixed(2)}, ${z.toFixed(2)}) m, tilted ${solution.tilt_deg.toFixed(1)}° from straight down`),
    el("div", { class: solution.accepted ? "verdict-ok" : "verdict-bad" }, solution.accepted ? "within the limits: can be saved" : solution.refusal),
    ...solution.warnings.map((w) => el("div", { class: "muted" }, w)),
  );
}

function body() {
  return { points: points.complete(), max_rms_px: overview.max_rms_px, max_ground_error_m: overview.max_ground_error_m };
}

async function preview() {
  const seq = ++previewSeq;
  status("solving…");
  try {
    const solution = await sendJson("POST", `/api/calibration/cameras/${encodeURIComponent(page.camera)}/solve`, body());
    if (seq !== previewSeq) return; // the points changed meanwhile
    setSolution(solution);
    status(solution.accepted ? "pose previewed; save it when the errors look right" : "pose previewed, but outside the limits", solution.accepted ? "ok" : "error");
  } catch (error) {
    if (seq !== previewSeq) return;
    setSolution(null);
    status(error.message, "error");
  }
}

async function save() {
  $("save").disabled = true;
  status("saving…");
  try {
    const saved = await sendJson("PUT", `/api/calibration/cameras/${encodeURIComponent(page.camera)}/extrinsics`, body());
    page.saved = saved;
    setSolution(saved);
    status(`saved into ${saved.site_file} (previous version: ${saved.backup}). Next: ${saved.next}`, "ok");
    await loadOverview(page.camera); // the plan shows the camera where it now hangs, with its coverage
    await loadFrame(page.camera); // a rendered grid is redrawn through the new pose: the points sit on its crossings
  } catch (error) {
    page.error = error.message;
    status(error.message, "error");
    $("save").disabled = false;
  }
}

async function loadOverview(selected) {
  overview = await getJson("/api/calibration");
  $("site-name").textContent = overview.site;
  $("site-banner").hidden = overview.editable;
  $("site-banner-text").textContent = overview.reason;
  const select = $("camera-select");
  select.replaceChildren(...overview.cameras.map((c) => el("option", { value: c.id }, c.drift.state === "moved" ? `${c.id} (moved)` : c.id)));
  select.value = selected || overview.cameras[0].id;
  plan.setSite(overview, select.value);
}

async function showCamera(cameraId) {
  page.camera = cameraId;
  page.ready = false;
  points.clear();
  plan.setSite(overview, cameraId);
  await loadFrame(cameraId);
  page.imageSize = [$("frame").naturalWidth, $("frame").naturalHeight];
  page.ready = true;
}

async function loadFrame(cameraId) {
  const grid = $("grid-overlay").checked ? "?grid=true" : "";
  const source = await image.load(`/api/calibration/cameras/${encodeURIComponent(cameraId)}/frame${grid}`);
  page.frameSource = source;
  $("frame-source").textContent = source === "live" ? "latest frame" : "no frame from this camera: the floor grid as the current calibration sees it";
  $("grid-overlay").disabled = source !== "live";
}

async function checks() {
  try {
    await refreshChecks({
      driftList: $("drift-list"),
      consistencyBody: $("consistency-body"),
      consistencyTable: $("consistency"),
      consistencyEmpty: $("consistency-empty"),
      updated: $("checks-updated"),
    });
  } catch (error) {
    $("checks-updated").textContent = error.message;
  }
}

const NUDGE = { ArrowLeft: [-1, 0], ArrowRight: [1, 0], ArrowUp: [0, -1], ArrowDown: [0, 1] };

/** Arrow keys move the selected point by one image pixel (a fifth with Shift), unless typing. */
function nudge(event) {
  const step = NUDGE[event.key];
  if (!step || event.target.closest("input, select, textarea")) return;
  event.preventDefault();
  const size = event.shiftKey ? 0.2 : 1;
  points.nudge(step[0] * size, step[1] * size);
}

async function start() {
  document.addEventListener("keydown", nudge);
  $("preview").addEventListener("click", preview);
  $("save").addEventListener("click", save);
  $("clear").addEventListener("click", () => points.clear());
  $("camera-select").addEventListener("change", (event) => showCamera(event.target.value).catch((e) => status(e.message, "error")));
  $("grid-overlay").addEventListener("change", () => showCamera(page.camera).catch((e) => status(e.message, "error")));
  try {
    const wanted = new URLSearchParams(location.search).get("camera");
    await loadOverview(wanted);
    await showCamera($("camera-select").value);
  } catch (error) {
    page.error = error.message;
    status(error.message, "error");
  }
  checks();
  setInterval(checks, CHECKS_EVERY_MS);
}

start();
