// What the engine is doing right now: the status bar, the channel meters and the
// armband's levels and contacts, all fed by the WebSocket `state` stream.

import { FLOOR_DBFS, channelColor, dbfs, formatNumber, levelNorm } from "./units.js";

const $ = (id) => document.getElementById(id);

function setText(id, text) {
  const node = $(id);
  if (node.textContent !== text) node.textContent = text;
}

// What the Underruns count means for this output (the sink's own rule): a sound card
// counts the blocks PortAudio reports it needed before they were ready; the null and
// capture outputs have no card and keep time with this machine's clock, so they count
// blocks whose turn came more than one block period late.
export function underrunMeaning(backend, blockMs) {
  const block = blockMs ? `${formatNumber(blockMs, 1)} ms` : "a block";
  if (backend === "sounddevice") {
    return (
      "Blocks the sound card needed before they were ready: each is a short gap or click. " +
      "A rising count means the machine is too busy or the block too small."
    );
  }
  return (
    "No sound card: this output keeps time with the machine's clock and plays nothing. " +
    `An underrun is a block whose turn came more than one block (${block}) late: the ` +
    "machine was too busy to run the engine on time. Nothing is heard either way; with a " +
    "sound card it would be a gap or a click."
  );
}

export class StatusView {
  constructor(armband) {
    this.armband = armband;
    this.meters = [];
  }

  setDevice(device) {
    setText("st-backend", device.backend || "–");
    const rate = device.sample_rate_hz;
    const blockMs = rate && device.block_frames ? (device.block_frames / rate) * 1000 : null;
    $("st-underruns").parentElement.title = underrunMeaning(device.backend, blockMs);
    setText("st-rate", rate ? `${rate.toLocaleString("en-US")} Hz` : "–");
    if (device.block_frames) {
      const ms = rate ? ` (${formatNumber((device.block_frames / rate) * 1000, 1)} ms)` : "";
      setText("st-block", `${device.block_frames} frames${ms}`);
    }
  }

  buildMeters(actuators) {
    const box = $("meters");
    box.replaceChildren();
    this.meters = actuators.map((a, index) => {
      const meter = document.createElement("div");
      meter.className = "meter";
      meter.setAttribute("role", "meter");
      meter.setAttribute("aria-label", `Actuator ${index + 1} level, dBFS`);
      meter.setAttribute("aria-valuemin", String(FLOOR_DBFS));
      meter.setAttribute("aria-valuemax", "0");
      meter.setAttribute("aria-valuenow", String(FLOOR_DBFS));
      meter.style.setProperty("--channel", channelColor(a.channel - 1));
      const label = document.createElement("span");
      label.className = "meter-label";
      label.textContent = String(index + 1);
      const track = document.createElement("span");
      track.className = "meter-track";
      const bar = document.createElement("span");
      bar.className = "meter-bar";
      track.appendChild(bar);
      const value = document.createElement("span");
      value.className = "meter-value";
      value.textContent = "–";
      meter.append(label, track, value);
      box.appendChild(meter);
      return { channel: a.channel, meter, bar, value };
    });
  }

  show(state) {
    const levels = state.levels || [];
    this.armband.setLevels(levels);
    for (const m of this.meters) {
      const level = Number(levels[m.channel - 1]) || 0;
      const db = dbfs(level);
      m.bar.style.transform = `scaleX(${levelNorm(level)})`;
      const text = db > FLOOR_DBFS ? `${Math.round(db)} dB` : "–";
      if (m.value.textContent !== text) m.value.textContent = text;
      m.meter.setAttribute("aria-valuenow", String(Math.max(FLOOR_DBFS, Math.round(db))));
    }
    this.armband.setContacts(state.contacts || []);
    setText("st-voices", String(state.active_voices ?? "–"));
    setText("st-contacts", state.contacts ? String(state.contacts.length) : "–");
    if (state.underruns !== undefined) setText("st-underruns", String(state.underruns));
    if (typeof state.output_latency_s === "number") {
      setText("st-latency", `${formatNumber(state.output_latency_s * 1000, 1)} ms`);
    }
  }

  // The connection is gone: show nothing rather than the last levels.
  clear() {
    this.show({ levels: [], contacts: [] });
    setText("st-voices", "–");
    setText("st-contacts", "–");
  }
}
