// The page: wires the armband, the live contacts, the designer, the status bar and the
// stop button to the service.

import { api } from "./api.js";
import { Armband } from "./armband.js";
import { GainChart } from "./chart.js";
import { Designer } from "./designer.js";
import { LiveTouch } from "./live.js";
import { Session } from "./socket.js";
import { FLOOR_DBFS, channelColor, dbfs, formatNumber, levelNorm } from "./units.js";

const $ = (id) => document.getElementById(id);
const MAX_ALERTS = 3;

// --- errors --------------------------------------------------------------------------

function showError(message) {
  const box = $("alerts");
  for (const existing of box.querySelectorAll(".alert")) {
    if (existing.dataset.message === message) existing.remove();
  }
  const alert = document.createElement("div");
  alert.className = "alert";
  alert.setAttribute("role", "alert");
  alert.dataset.message = message;
  const text = document.createElement("p");
  text.textContent = message;
  const close = document.createElement("button");
  close.type = "button";
  close.className = "alert-close";
  close.setAttribute("aria-label", "Dismiss this message");
  close.textContent = "×";
  close.addEventListener("click", () => alert.remove());
  alert.append(text, close);
  box.prepend(alert);
  while (box.childElementCount > MAX_ALERTS) box.lastElementChild.remove();
}

// --- status bar and meters -------------------------------------------------------------

function setStatus(id, text) {
  const node = $(id);
  if (node.textContent !== text) node.textContent = text;
}

function showDevice(device) {
  setStatus("st-backend", device.backend || "–");
  setStatus("st-rate", device.sample_rate_hz ? `${device.sample_rate_hz.toLocaleString("en-US")} Hz`
    : "–");
  if (device.block_frames) {
    const ms = device.sample_rate_hz ? ` (${formatNumber((device.block_frames / device.sample_rate_hz) * 1000, 1)} ms)` : "";
    setStatus("st-block", `${device.block_frames} frames${ms}`);
  }
}

function buildMeters(device) {
  const box = $("meters");
  box.replaceChildren();
  const meters = [];
  device.actuators.forEach((a, index) => {
    const meter = document.createElement("div");
    meter.className = "meter";
    meter.setAttribute("role", "meter");
    meter.setAttribute("aria-label", `Actuator ${index + 1} level, dBFS`);
    meter.setAttribute("aria-valuemin", String(FLOOR_DBFS));
    meter.setAttribute("aria-valuemax", "0");
    meter.setAttribute("aria-valuenow", String(FLOOR_DBFS));
    meter.style.setProperty("--channel", channelColor(a.channel - 1));
    const track = document.createElement("span");
    track.className = "meter-track";
    const bar = document.createElement("span");
    bar.className = "meter-bar";
    track.appendChild(bar);
    const label = document.createElement("span");
    label.className = "meter-label";
    label.textContent = String(index + 1);
    const value = document.createElement("span");
    value.className = "meter-value";
    value.textContent = "–";
    meter.append(label, track, value);
    box.appendChild(meter);
    meters.push({ channel: a.channel, meter, bar, value });
  });
  return meters;
}

function showLevels(meters, levels) {
  for (const m of meters) {
    const level = Number(levels[m.channel - 1]) || 0;
    const db = dbfs(level);
    m.bar.style.transform = `scaleX(${levelNorm(level)})`;
    const text = db > FLOOR_DBFS ? `${Math.round(db)} dB` : "–";
    if (m.value.textContent !== text) m.value.textContent = text;
    m.meter.setAttribute("aria-valuenow", String(Math.max(FLOOR_DBFS, Math.round(db))));
  }
}

// --- start-up ------------------------------------------------------------------------

async function main() {
  const session = new Session(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
  const liveControls = {
    carrier: $("live-carrier"), freq: $("live-freq"), intensity: $("live-intensity"), law: $("live-law"),
  };
  const liveSettings = () => {
    const kind = liveControls.carrier.value;
    const carrier = kind === "noise" ? { kind } : { kind, freq_hz: Number(liveControls.freq.value) };
    return {
      carrier, intensity: Number(liveControls.intensity.value), law: liveControls.law.value,
    };
  };
  const live = new LiveTouch(session, liveSettings);
  let designer = null;
  const armband = new Armband($("armband"), {
    down: (id, pos) => live.down(id, pos),
    move: (id, pos) => live.move(id, pos),
    up: (id) => live.up(id),
    drawn: (points) => designer && designer.setDrawn(points),
    addPoint: (point) => designer && designer.addDrawnPoint(point),
  });
  const chart = new GainChart($("chart"));

  liveControls.intensity.addEventListener("input", () => {
    $("live-intensity-out").textContent = formatNumber(liveControls.intensity.value);
    live.nudge();
  });
  liveControls.carrier.addEventListener("change", () => {
    liveControls.freq.disabled = liveControls.carrier.value === "noise";
    live.retouch();
  });
  liveControls.freq.addEventListener("change", () => live.retouch());
  liveControls.law.addEventListener("change", () => live.retouch());

  for (const radio of document.querySelectorAll("input[name=drag-mode]")) {
    radio.addEventListener("change", () => armband.setMode(radio.value));
  }
  $("draw-path").addEventListener("click", () => {
    document.querySelector("input[name=drag-mode][value=draw]").checked = true;
    armband.setMode("draw");
    $("armband").focus();
  });

  const stop = async () => {
    live.stopped();
    if (designer) designer.stopped();
    session.send({ type: "stop" });
    const button = $("stop");
    button.classList.add("pressed");
    setTimeout(() => button.classList.remove("pressed"), 200);
    try {
      await api.stop();
    } catch (exc) {
      showError(`Stop failed: ${exc.message}`);
    }
  };
  $("stop").addEventListener("click", stop);
  document.addEventListener("keydown", (event) => {
    if (event.key === "Escape") {
      event.preventDefault();
      stop();
    }
  });

  session.addEventListener("connection", ({ detail }) => {
    const box = $("connection");
    box.dataset.state = detail.state;
    $("connection-text").textContent = detail.state === "connected" ? "Live"
      : detail.state === "connecting" ? "Connecting…"
        : `Disconnected, retrying in ${formatNumber(detail.retryInS, 1)} s`;
  });
  session.addEventListener("error", ({ detail }) => {
    showError(detail.message || `The service refused a message (${detail.code || "error"}).`);
  });
  session.addEventListener("released", ({ detail }) => {
    showError(`The service released ${detail.contacts ? detail.contacts.length : "the"} contact(s)`
      + ` (${detail.reason || "released"}).`);
  });

  let device;
  try {
    device = await api.device();
  } catch (exc) {
    showError(`Cannot load the device: ${exc.message}`);
    return;
  }
  armband.build(device);
  showDevice(device);
  const meters = buildMeters(device);
  const channelLabels = () => {
    const labels = [];
    device.actuators.forEach((a, index) => { labels[a.channel - 1] = String(index + 1); });
    return labels;
  };
  designer = new Designer({ armband, chart, session, showError, channelLabels });

  session.addEventListener("welcome", ({ detail }) => {
    if (detail.device) showDevice({ ...device, ...detail.device, backend: device.backend });
  });
  session.addEventListener("state", ({ detail }) => {
    const levels = detail.levels || [];
    armband.setLevels(levels);
    showLevels(meters, levels);
    armband.setContacts(detail.contacts || []);
    setStatus("st-voices", String(detail.active_voices ?? "–"));
    setStatus("st-contacts", String((detail.contacts || []).length));
    if (detail.underruns !== undefined) setStatus("st-underruns", String(detail.underruns));
    if (detail.output_latency_s !== undefined && detail.output_latency_s !== null) {
      setStatus("st-latency", `${formatNumber(detail.output_latency_s * 1000, 1)} ms`);
    }
  });
  session.start();

  try {
    await designer.load();
  } catch (exc) {
    showError(`Cannot load the presets: ${exc.message}`);
  }
  document.body.dataset.ready = "true";
}

main();
