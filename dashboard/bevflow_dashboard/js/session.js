// Who is logged in: their name and a way out in the top bar, and the page adjusted to their role
// (viewers see no Acknowledge buttons, only admins the calibration link). The gateway enforces
// the roles either way; this only spares people buttons that would answer "forbidden".

import { getJson } from "./api.js";
import { el } from "./dom.js";

/** Fetch `/api/auth/me` and adjust the page; resolves to {name, role, auth} (null if unknown). */
export async function showSession({ badge, calibrationLink }) {
  let me;
  try {
    me = await getJson("/api/auth/me");
  } catch {
    return null; // the banner already reports a gateway that does not answer
  }
  document.body.dataset.role = me.role;
  calibrationLink.hidden = me.role !== "admin";
  if (me.auth) {
    badge.replaceChildren(
      el("span", { class: "session-name", title: `Logged in as ${me.name} (${me.role})` }, `${me.name} · ${me.role}`),
      el("a", { class: "button button-quiet", href: "/logout", id: "logout" }, "Log out"),
    );
    badge.hidden = false;
  }
  return me;
}
