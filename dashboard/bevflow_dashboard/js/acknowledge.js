// Alert acknowledgements, kept by the gateway: who acknowledged which alert, and when.
//
// `loadAcknowledgements` fetches the recent ones and returns a Map (alert id -> {at, by, note})
// that stays live: acknowledgements made on other screens arrive over /ws/acknowledgements and
// are added to it, and the alert feed, which re-renders every second, shows them. After a lost
// connection the list is fetched again, so none made meanwhile is missed.

import { LiveSocket, getJson } from "./api.js";

const live = new Map(); // site -> {records, socket}

function record(ack) {
  return { at: ack.time, by: ack.user, note: ack.note };
}

function remember(records, acks) {
  // Acknowledgements come oldest first; the first one is the one shown ("acknowledged 14:02").
  for (const ack of acks) if (!records.has(ack.alert_id)) records.set(ack.alert_id, record(ack));
}

/** Every acknowledgement the gateway knows of recent alerts: a Map from alert id to
 * {at: ISO time, by: user, note}, kept up to date with those made on other screens. */
export async function loadAcknowledgements(site) {
  const known = live.get(site);
  if (known) return known.records;
  const records = new Map();
  const refresh = async () => remember(records, await getJson("/api/acknowledgements"));
  try {
    await refresh();
  } catch {
    // the gateway is unreachable: the socket below catches up when it is back
  }
  const socket = new LiveSocket("/ws/acknowledgements", {
    onMessage: (ack) => remember(records, [ack]),
    onStatus: ({ state }) => state === "open" && refresh().catch(() => {}),
  });
  socket.start();
  live.set(site, { records, socket });
  return records;
}

/** POST `body` as JSON to `path`; the answer, or an Error saying why not. */
async function post(path, body) {
  let response;
  try {
    response = await fetch(path, {
      method: "POST",
      headers: { "Content-Type": "application/json", Accept: "application/json" },
      body: JSON.stringify(body),
      credentials: "same-origin",
    });
  } catch {
    throw new Error("the gateway does not answer");
  }
  const answer = await response.json().catch(() => ({}));
  if (response.status === 401) location.assign(`/login.html?next=${encodeURIComponent(location.pathname)}`);
  if (!response.ok) throw new Error(typeof answer.detail === "string" ? answer.detail : `HTTP ${response.status}`);
  return answer;
}

/** Acknowledge the alerts `ids` of `site` in one request; resolves to [[id, {at, by, note}], ...] for those stored. */
export async function acknowledgeAlerts(site, ids, note = "") {
  const answer = await post("/api/alerts/acknowledge", { ids, note });
  const records = live.get(site)?.records;
  return answer.acknowledged.map((ack) => {
    if (records && !records.has(ack.alert_id)) records.set(ack.alert_id, record(ack));
    return [ack.alert_id, records?.get(ack.alert_id) || record(ack)];
  });
}

/**
 * Acknowledge alert `alertId` of `site`; resolves to {at, by, note} once the gateway has stored it.
 * Throws an Error saying why not (not allowed for a viewer, unknown alert, gateway unreachable).
 */
export async function acknowledgeAlert(site, alertId, note = "") {
  const stored = record(await post(`/api/alerts/${encodeURIComponent(alertId)}/acknowledge`, { note }));
  const records = live.get(site)?.records;
  if (records && !records.has(alertId)) records.set(alertId, stored);
  return records?.get(alertId) || stored;
}
