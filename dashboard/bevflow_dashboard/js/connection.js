// Whether the dashboard is live: each websocket and the REST polls report here, and the banner
// says so as soon as any of them has lost the gateway.

export class ConnectionMonitor {
  constructor(banner, detail, { onChange = () => {} } = {}) {
    this.banner = banner;
    this.detail = detail;
    this.onChange = onChange;
    this.problems = new Map(); // source -> text
  }

  /** `source` ("tracks", "alerts", "rest") works again. */
  ok(source) {
    if (this.problems.delete(source)) this.render();
  }

  /** `source` lost the gateway; `text` says what happens next. */
  lost(source, text) {
    this.problems.set(source, text);
    this.render();
  }

  get live() {
    return this.problems.size === 0;
  }

  render() {
    this.banner.hidden = this.live;
    const texts = [...new Set(this.problems.values())];
    this.detail.textContent = texts.join(" ");
    document.body.dataset.connection = this.live ? "live" : "lost";
    this.onChange(this.live);
  }
}
