// The checks of the calibration page: whether the tracker reports a camera as moved, and how far
// apart overlapping cameras put the same people (from /api/calibration/drift and /consistency).

import { getJson } from "./api.js";
import { el } from "./dom.js";

export async function refreshChecks({ driftList, consistencyBody, consistencyTable, consistencyEmpty, updated }) {
  const [drift, consistency] = await Promise.all([getJson("/api/calibration/drift"), getJson("/api/calibration/consistency")]);
  driftList.replaceChildren(
    ...drift.map((d) =>
      el(
        "li",
        {
          class: "badge",
          "data-state": d.state,
          "data-camera": d.camera,
          title: d.state === "moved" ? `moved by ${d.shift_m.toFixed(2)} m against ${d.reference_camera} since ${d.since}` : "no shift reported",
        },
        d.camera,
        el("span", { class: "badge-state" }, d.state === "moved" ? `moved ${d.shift_m.toFixed(2)} m` : "ok"),
      ),
    ),
  );
  const rows = consistency.pairs.map((p) => {
    const verdict = !p.judged ? "too few" : p.agrees ? "agree" : "disagree";
    return el(
      "tr",
      { "data-pair": `${p.camera_a}/${p.camera_b}` },
      el("td", {}, `${p.camera_a} / ${p.camera_b}`),
      el("td", {}, p.samples),
      el("td", {}, `${p.median_offset_m.toFixed(2)} m`),
      el("td", {}, `${p.spread_m.toFixed(2)} m`),
      el("td", { "data-verdict": verdict }, verdict === "disagree" ? `more than ${consistency.tolerance_m} m apart` : verdict),
    );
  });
  consistencyBody.replaceChildren(...rows);
  consistencyTable.hidden = rows.length === 0;
  consistencyEmpty.hidden = rows.length > 0;
  updated.textContent = `${consistency.ticks} recent ticks · ${new Date().toLocaleTimeString([], { hour12: false })}`;
}
