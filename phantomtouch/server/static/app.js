// The page: wires the armband, the live contacts, the designer, the status view, the
// .tact panel, the bHaptics games panel and the stop button to the service.

import { api, token } from "./api.js";
import { Armband } from "./armband.js";
import { GainChart } from "./chart.js";
import { Designer } from "./designer.js";
import { LiveTouch } from "./live.js";
import { Session } from "./socket.js";
import { StatusView } from "./status.js";
import { TactPanel } from "./tact.js";
import { formatNumber } from "./units.js";
import { WearerPanel } from "./wearer.js";
import { WorkspacesPanel } from "./workspaces.js";

const $ = (id) => document.getElementById(id);
const MAX_ALERTS = 3;

// A server error, shown until dismissed; the same message again replaces the old one.
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

function liveSettings() {
  const kind = $("live-carrier").value;
  const carrier = kind === "noise" ? { kind } : { kind, freq_hz: Number($("live-freq").value) };
  return { carrier, intensity: Number($("live-intensity").value), law: $("live-law").value };
}

function wireLiveControls(live) {
  $("live-intensity").addEventListener("input", () => {
    $("live-intensity-out").textContent = formatNumber($("live-intensity").value);
    live.nudge();
  });
  $("live-carrier").addEventListener("change", () => {
    $("live-freq").disabled = $("live-carrier").value === "noise";
    live.retouch();
  });
  $("live-freq").addEventListener("change", () => live.retouch());
  $("live-law").addEventListener("change", () => live.retouch());
}

function wireConnection(session, status, live) {
  session.addEventListener("connection", ({ detail }) => {
    if (detail.state === "disconnected") status.clear();
    $("connection").dataset.state = detail.state;
    $("connection-text").textContent = detail.state === "connected" ? "Live"
      : detail.state === "connecting" ? "Connecting…"
        : `Disconnected, retrying in ${formatNumber(detail.retryInS, 1)} s`;
  });
  session.addEventListener("state", ({ detail }) => status.show(detail));
  session.addEventListener("error", ({ detail }) => {
    showError(detail.message || `The service refused a message (${detail.code || "error"}).`);
  });
  session.addEventListener("released", ({ detail }) => {
    live.released(detail.contacts || []);
    if (detail.reason === "watchdog") {
      showError("The service released your touch: it heard nothing from this page for too "
        + "long (watchdog). Touch again to continue.");
    }
  });
}

async function main() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  const query = token ? `?token=${encodeURIComponent(token)}` : "";
  const session = new Session(`${scheme}://${location.host}/ws${query}`);
  const live = new LiveTouch(session, liveSettings);
  let designer = null;
  const armband = new Armband($("armband"), {
    down: (id, pos) => live.down(id, pos),
    move: (id, pos) => live.move(id, pos),
    up: (id) => live.up(id),
    drawn: (points) => designer && designer.setDrawn(points),
    addPoint: (point) => designer && designer.addDrawnPoint(point),
  }, $("pointer-readout"));
  const status = new StatusView(armband);
  wireLiveControls(live);
  wireConnection(session, status, live);

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
    $("stop").classList.add("pressed");
    setTimeout(() => $("stop").classList.remove("pressed"), 200);
    try {
      await api.stop();
    } catch (exc) {
      showError(`Stop failed: ${exc.message}`);
    }
  };
  $("stop").addEventListener("click", stop);
  document.addEventListener("keydown", (event) => {
    if (event.key !== "Escape") return;
    event.preventDefault();
    stop();
  });

  let device;
  try {
    device = await api.device();
  } catch (exc) {
    showError(`Cannot load the device: ${exc.message}`);
    return;
  }
  armband.build(device);
  status.setDevice(device);
  status.buildMeters(device.actuators);
  session.addEventListener("welcome", ({ detail }) => status.setDevice({ ...device, ...detail.device }));
  const channelLabels = () => {
    const labels = [];
    device.actuators.forEach((a, index) => { labels[a.channel - 1] = String(index + 1); });
    return labels;
  };
  designer = new Designer({ armband, chart: new GainChart($("chart")), session, showError, channelLabels });
  new WearerPanel({ device, showError });
  const tact = new TactPanel({ showError });
  const games = new WorkspacesPanel({ showError });
  session.start();
  try {
    await designer.load();
  } catch (exc) {
    showError(`Cannot load the presets: ${exc.message}`);
  }
  await tact.loadList();
  await games.loadList();
  document.body.dataset.ready = "true";
}

main();
