// How times, durations and alert types read on screen.

const NS_PER_MS = 1e6;

/** A Date from nanoseconds since the epoch (a number or a numeric string). */
export function dateFromNs(ns) {
  return new Date(Number(ns) / NS_PER_MS);
}

/** "14:03:27", in the browser's time zone (the control room's). */
export function clockTime(date) {
  return date.toLocaleTimeString([], { hour: "2-digit", minute: "2-digit", second: "2-digit", hour12: false });
}

/** "14:03". */
export function shortTime(date) {
  return date.toLocaleTimeString([], { hour: "2-digit", minute: "2-digit", hour12: false });
}

/** "45 s", "3 min 05 s", "1 h 12 min". */
export function duration(seconds) {
  const s = Math.max(0, Math.round(seconds));
  if (s < 60) return `${s} s`;
  if (s < 3600) return `${Math.floor(s / 60)} min ${String(s % 60).padStart(2, "0")} s`;
  return `${Math.floor(s / 3600)} h ${String(Math.floor((s % 3600) / 60)).padStart(2, "0")} min`;
}

export const ALERT_TYPES = {
  distance_incident: { label: "Too close", severity: "alert" },
  distance_violation: { label: "Too close (pair)", severity: "alert" },
  over_capacity: { label: "Over capacity", severity: "alert" },
  camera_down: { label: "Camera down", severity: "alert" },
  calibration_drift: { label: "Calibration drift", severity: "info" },
  camera_up: { label: "Camera back up", severity: "info" },
};

export function alertLabel(type) {
  return (ALERT_TYPES[type] || { label: type.replaceAll("_", " ") }).label;
}

export function alertSeverity(type) {
  return (ALERT_TYPES[type] || { severity: "info" }).severity;
}

/** "1.2 m" with one decimal. */
export function metres(value) {
  return `${Number(value).toFixed(1)} m`;
}
