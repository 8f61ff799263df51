// What an alert says in the feed, by type: who, how close, how many, which camera.

import { el } from "./dom.js";
import { metres } from "./format.js";

const MAX_PEOPLE_LINKS = 6; // an incident lists its first people as links, then "+ n more"

/** Buttons for track ids, joined "a, b and c"; `onTrack(id)` opens that person. */
function peopleLinks(ids, onTrack) {
  const shown = ids.slice(0, MAX_PEOPLE_LINKS);
  const buttons = shown.map((id) => el("button", { type: "button", class: "track-link", "data-track": id, onclick: () => onTrack(id) }, `#${id}`));
  const joined = buttons.flatMap((button, i) => (i ? [i === buttons.length - 1 && ids.length <= shown.length ? " and " : ", ", button] : [button]));
  if (ids.length > shown.length) joined.push(` + ${ids.length - shown.length} more`);
  return joined;
}

/** The people of an incident a supervisor looks for: those in it now, or everyone once it ended. */
export function incidentPeople(alert) {
  const event = alert.event || {};
  return alert.active && event.current?.length ? event.current : alert.tracks;
}

/** The children of an alert's body line. */
export function alertDetail(alert, onTrack) {
  const event = alert.event || {};
  const people = peopleLinks(alert.tracks, onTrack);
  switch (alert.type) {
    case "distance_incident": {
      const now = alert.active ? `${event.current?.length ?? 0} now, ` : "";
      return [
        `${event.people} people too close (${now}closest ${metres(event.min_distance_m)}, limit ${metres(event.limit_m)}): `,
        ...peopleLinks(incidentPeople(alert), onTrack),
      ];
    }
    case "distance_violation":
      return ["People ", ...people, ` ${metres(event.min_distance_m)} apart (limit ${metres(event.limit_m)})`];
    case "over_capacity":
      return [`Peak ${event.peak} people, capacity ${event.capacity}`];
    case "camera_down":
      return [`Camera ${event.camera}${event.reason ? `: ${event.reason}` : ""}`];
    case "camera_up":
      return [`Camera ${event.camera} is sending frames again`];
    case "calibration_drift":
      return [`Camera ${event.camera} shifted ${metres(event.shift_m)}${event.reference_camera ? ` against ${event.reference_camera}` : ""}`];
    default:
      return alert.tracks.length ? ["People ", ...people] : [];
  }
}

/** Whether an ended alert still asks to be acknowledged (a short, minor incident that is over does not). */
export function wantsAcknowledgement(alert) {
  return alert.event?.needs_acknowledgement !== false;
}
