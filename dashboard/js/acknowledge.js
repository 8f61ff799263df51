// Alert acknowledgements.
//
// The gateway has no acknowledgement endpoint yet, so they are kept in this browser's localStorage,
// per site: an operator's acknowledgements survive a page reload but are not shared with other
// screens. When the gateway stores them (with the user who acknowledged), only
// `acknowledgeAlert` (becomes a POST) and `loadAcknowledgements` (becomes a GET, or a field of each
// alert) change; the rest of the dashboard goes through these two functions.

const MAX_KEPT = 1000; // acknowledgements of alerts long gone are dropped, oldest first

function storageKey(site) {
  return `bevflow.acknowledged.${site}`;
}

function readStore(site) {
  try {
    const stored = JSON.parse(localStorage.getItem(storageKey(site)) || "{}");
    return stored && typeof stored === "object" ? stored : {};
  } catch {
    return {}; // unreadable (another version, or storage disabled): start afresh
  }
}

/** Every acknowledgement known for `site`: a Map from alert id to {at: ISO time}. */
export async function loadAcknowledgements(site) {
  return new Map(Object.entries(readStore(site)));
}

/**
 * Acknowledge alert `alertId` of `site`; resolves to {at: ISO time} once recorded.
 * Later: `POST /api/alerts/{alertId}/acknowledge` and return the gateway's record.
 */
export async function acknowledgeAlert(site, alertId) {
  const store = readStore(site);
  const record = { at: new Date().toISOString() };
  store[alertId] = record;
  const ids = Object.keys(store);
  for (const old of ids.slice(0, Math.max(0, ids.length - MAX_KEPT))) delete store[old];
  try {
    localStorage.setItem(storageKey(site), JSON.stringify(store));
  } catch {
    // storage full or disabled: the acknowledgement still holds until the page is reloaded
  }
  return record;
}
