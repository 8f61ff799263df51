// Sound and desktop notifications for what must not wait: a zone over capacity, a large incident.
// Off by default and per browser (localStorage): a control room turns it on at its own screens.

const KEY = "bevflow.notify";

/** Whether an alert is worth interrupting someone for. */
export function urgent(alert) {
  if (!alert.active) return false;
  return alert.type === "over_capacity" || (alert.type === "distance_incident" && alert.event?.severity === "high");
}

export class Notifier {
  /** @param {HTMLInputElement} toggle  the checkbox that turns it on and off */
  constructor(toggle) {
    this.toggle = toggle;
    this.told = new Set(); // alert ids already notified: one notification per alert, however often it changes
    this.count = 0;
    toggle.checked = localStorage.getItem(KEY) === "on";
    toggle.addEventListener("change", () => {
      localStorage.setItem(KEY, toggle.checked ? "on" : "off");
      if (toggle.checked && "Notification" in window && Notification.permission === "default") Notification.requestPermission();
    });
  }

  /** Take an alert that just arrived or changed; notifies once if it is urgent and notifications are on. */
  consider(alert, text) {
    if (!this.toggle.checked || !urgent(alert) || this.told.has(alert.id)) return;
    this.told.add(alert.id);
    this.count += 1;
    beep();
    if ("Notification" in window && Notification.permission === "granted") new Notification("bevflow", { body: text, tag: alert.id });
  }
}

function beep() {
  try {
    const audio = new AudioContext();
    const tone = audio.createOscillator();
    const gain = audio.createGain();
    tone.frequency.value = 880;
    gain.gain.setValueAtTime(0.2, audio.currentTime);
    gain.gain.exponentialRampToValueAtTime(0.001, audio.currentTime + 0.6);
    tone.connect(gain).connect(audio.destination);
    tone.start();
    tone.stop(audio.currentTime + 0.6);
  } catch {
    // no audio output (or not allowed before a click): the desktop notification still goes
  }
}
