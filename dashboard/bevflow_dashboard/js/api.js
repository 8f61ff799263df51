// Talking to the gateway: JSON over REST with a timeout, and websockets that reconnect by themselves.

export class ApiError extends Error {}

/** GET `path` and parse its JSON; ApiError on a network failure, a timeout or an HTTP error (but the
 * statuses in `alsoOk`, whose body is the answer: /api/health says 503 while the site is not ok). */
export async function getJson(path, { timeoutMs = 5000, alsoOk = [] } = {}) {
  const abort = new AbortController();
  const timer = setTimeout(() => abort.abort(), timeoutMs);
  try {
    const response = await fetch(path, { signal: abort.signal, headers: { Accept: "application/json" } });
    if (response.status === 401) {
      // The session ended (expired, or logged out elsewhere): log in again, then come back here.
      location.assign(`/login.html?next=${encodeURIComponent(location.pathname + location.search)}`);
    }
    if (!response.ok && !alsoOk.includes(response.status)) {
      const body = await response.json().catch(() => ({}));
      throw new ApiError(`${path}: HTTP ${response.status} ${body.message || body.detail || ""}`.trim());
    }
    return await response.json();
  } catch (error) {
    if (error instanceof ApiError) throw error;
    throw new ApiError(`${path}: ${error.name === "AbortError" ? "no answer" : "unreachable"}`);
  } finally {
    clearTimeout(timer);
  }
}

/** The websocket URL of `path` on the host that served this page. */
export function socketUrl(path) {
  const scheme = location.protocol === "https:" ? "wss:" : "ws:";
  return `${scheme}//${location.host}${path}`;
}

/**
 * A websocket that reconnects with exponential backoff (with jitter, so that many dashboards do not
 * all knock at once after a gateway restart) and hands each JSON message to `onMessage`.
 * `onStatus({state, attempt, retryInMs})` reports "connecting", "open" and "closed".
 */
export class LiveSocket {
  constructor(path, { onMessage, onStatus = () => {}, minDelayMs = 500, maxDelayMs = 10000 }) {
    this.path = path;
    this.onMessage = onMessage;
    this.onStatus = onStatus;
    this.minDelayMs = minDelayMs;
    this.maxDelayMs = maxDelayMs;
    this.attempt = 0;
    this.socket = null;
    this.timer = null;
    this.stopped = true;
  }

  start() {
    this.stopped = false;
    this.connect();
  }

  stop() {
    this.stopped = true;
    clearTimeout(this.timer);
    if (this.socket) this.socket.close();
  }

  connect() {
    this.onStatus({ state: "connecting", attempt: this.attempt });
    const socket = new WebSocket(socketUrl(this.path));
    this.socket = socket;
    socket.addEventListener("open", () => {
      this.attempt = 0;
      this.onStatus({ state: "open", attempt: 0 });
    });
    socket.addEventListener("message", (event) => {
      let message;
      try {
        message = JSON.parse(event.data);
      } catch {
        return; // the gateway only sends JSON; anything else is not ours to show
      }
      this.onMessage(message);
    });
    // "error" is always followed by "close", which is where reconnecting happens.
    socket.addEventListener("close", () => {
      if (this.socket !== socket || this.stopped) return;
      const retryInMs = this.nextDelay();
      this.attempt += 1;
      this.onStatus({ state: "closed", attempt: this.attempt, retryInMs });
      this.timer = setTimeout(() => this.connect(), retryInMs);
    });
  }

  nextDelay() {
    const base = Math.min(this.maxDelayMs, this.minDelayMs * 2 ** this.attempt);
    return Math.round(base * (0.75 + 0.5 * Math.random()));
  }
}

/** Call `task` now and then every `periodMs` after it settles (calls never overlap). `task`
 * reports its own failures; one that throws is simply tried again next period. */
export function every(periodMs, task) {
  let timer = null;
  const run = async () => {
    try {
      await task();
    } catch {
      // already reported by the task
    } finally {
      timer = setTimeout(run, periodMs);
    }
  };
  run();
  return () => clearTimeout(timer);
}
