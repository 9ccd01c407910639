// The WebSocket session (docs/protocol.md, "WebSocket /ws"): hello/welcome, a `state`
// subscription, pings that keep the server's watchdog fed, and reconnection with
// exponential back-off when the connection drops.

const STATE_RATE_HZ = 30;
const FIRST_RETRY_S = 0.5;
const MAX_RETRY_S = 10;

export class Session extends EventTarget {
  constructor(url) {
    super();
    this.url = url;
    this.socket = null;
    this.ready = false;
    this.retryS = FIRST_RETRY_S;
    this.retryTimer = 0;
    this.pingTimer = 0;
    this.clockOffsetS = null;
    this.connects = 0;
  }

  start() {
    this.connect();
  }

  connect() {
    clearTimeout(this.retryTimer);
    this.emit("connection", { state: "connecting" });
    const socket = new WebSocket(this.url);
    this.socket = socket;
    socket.addEventListener("open", () => {
      this.connects += 1;
      this.clockOffsetS = null;
      this.send({ type: "hello", client: "phantomtouch-web", protocol: 1 });
    });
    socket.addEventListener("message", (event) => this.receive(event.data));
    socket.addEventListener("close", (event) => {
      if (this.socket !== socket) return;
      this.dropped(event.code);
    });
  }

  dropped(code) {
    this.ready = false;
    this.socket = null;
    clearInterval(this.pingTimer);
    const delayS = this.retryS * (0.8 + 0.4 * Math.random());
    this.retryS = Math.min(this.retryS * 2, MAX_RETRY_S);
    this.emit("connection", { state: "disconnected", retryInS: delayS, code });
    this.retryTimer = setTimeout(() => this.connect(), delayS * 1000);
  }

  receive(text) {
    let message;
    try {
      message = JSON.parse(text);
    } catch {
      return;
    }
    if (typeof message.server_time_s === "number") this.syncClock(message.server_time_s);
    if (message.type === "welcome") {
      this.ready = true;
      this.retryS = FIRST_RETRY_S;
      const watchdogS = Number(message.watchdog_s) || 2;
      clearInterval(this.pingTimer);
      this.pingTimer = setInterval(
        () => this.send({ type: "ping" }),
        Math.max(100, Math.min(1000, (watchdogS * 1000) / 4)),
      );
      this.send({ type: "subscribe", rate_hz: STATE_RATE_HZ });
      this.emit("connection", { state: "connected" });
    }
    this.emit(message.type, message);
  }

  // Server clock = local clock + offset. A message left the server before it arrived
  // here, so each sample underestimates the offset: keep the largest one seen.
  syncClock(serverTimeS) {
    const offset = serverTimeS - performance.now() / 1000;
    if (this.clockOffsetS === null || offset > this.clockOffsetS) this.clockOffsetS = offset;
  }

  serverNowS() {
    return this.clockOffsetS === null ? null : performance.now() / 1000 + this.clockOffsetS;
  }

  send(message) {
    if (!this.socket || this.socket.readyState !== WebSocket.OPEN) return false;
    this.socket.send(JSON.stringify(message));
    return true;
  }

  emit(type, detail) {
    this.dispatchEvent(new CustomEvent(type, { detail }));
  }
}
