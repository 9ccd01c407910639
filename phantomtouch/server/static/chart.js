// The gain curves of a plan on a canvas: one lane per output channel over time, like the
// paper's Fig. 3, with a playhead while the pattern plays.

import { channelColor, formatNumber } from "./units.js";

const LANE_PX = 30;
const LANE_GAP_PX = 6;
const AXIS_PX = 30;
const LEFT_PX = 44;
const RIGHT_PX = 12;
const TOP_PX = 22;
const NICE_STEPS_S = [0.05, 0.1, 0.2, 0.25, 0.5, 1, 2, 5, 10, 15, 30, 60, 120, 300, 600, 1800];

export class GainChart {
  constructor(canvas) {
    this.canvas = canvas;
    this.curves = null;
    this.labels = [];
    this.playheadS = null;
    this.base = document.createElement("canvas");
    new ResizeObserver(() => this.redraw()).observe(canvas);
  }

  // curves: {times_s, gains: [[g per channel], ...]} sampled over [0, durationS);
  // labels: the name of each channel's lane.
  show(curves, labels, durationS) {
    this.curves = curves && curves.times_s && curves.times_s.length ? curves : null;
    this.durationS = durationS;
    this.labels = labels;
    this.canvas.setAttribute("aria-label", this.describe());
    this.redraw();
  }

  // The chart in words, for screen readers: its span and the strongest actuator.
  describe() {
    const curves = this.curves;
    if (!curves) return "Gain of each actuator over time: no plan.";
    let peak = 0;
    let loudest = 0;
    curves.gains.forEach((row) => row.forEach((g, c) => {
      if (g > peak) [peak, loudest] = [g, c];
    }));
    return `Gain of each of ${this.channelCount()} actuators over `
      + `${formatNumber(this.durationS, 2)} s; the strongest is actuator `
      + `${this.labels[loudest] || loudest + 1} with a peak gain of ${formatNumber(peak, 4)}.`;
  }

  setPlayhead(timeS) {
    if (timeS === this.playheadS) return;
    this.playheadS = timeS;
    this.paint();
  }

  channelCount() {
    if (!this.curves) return this.labels.length || 8;
    return this.curves.gains[0] ? this.curves.gains[0].length : 0;
  }

  redraw() {
    const channels = this.channelCount();
    const cssWidth = Math.max(200, this.canvas.clientWidth);
    const cssHeight = TOP_PX + channels * (LANE_PX + LANE_GAP_PX) + AXIS_PX;
    const ratio = window.devicePixelRatio || 1;
    this.canvas.style.height = `${cssHeight}px`;
    for (const c of [this.canvas, this.base]) {
      c.width = Math.round(cssWidth * ratio);
      c.height = Math.round(cssHeight * ratio);
    }
    const ctx = this.base.getContext("2d");
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    this.size = { width: cssWidth, height: cssHeight, ratio };
    this.drawBase(ctx, cssWidth, channels);
    this.paint();
  }

  drawBase(ctx, width, channels) {
    const style = getComputedStyle(this.canvas);
    const ink = style.getPropertyValue("--chart-ink").trim() || "#334155";
    const grid = style.getPropertyValue("--chart-grid").trim() || "#e2e8f0";
    const plotWidth = width - LEFT_PX - RIGHT_PX;
    ctx.clearRect(0, 0, width, this.size.height);
    ctx.font = "12px system-ui, sans-serif";
    ctx.textBaseline = "middle";
    const curves = this.curves;
    const times = curves ? curves.times_s : [];
    const span = Math.max(1e-9, curves ? this.durationS : 1);
    this.timeToX = (t) => LEFT_PX + (t / span) * plotWidth;
    let peak = 0;
    if (curves) for (const row of curves.gains) for (const g of row) peak = Math.max(peak, g);
    const scale = peak > 0 ? 1 / peak : 1;

    const step = NICE_STEPS_S.find((s) => span / s <= 10) || span / 10;
    const lanesBottom = TOP_PX + channels * (LANE_PX + LANE_GAP_PX);
    ctx.strokeStyle = grid;
    ctx.lineWidth = 1;
    ctx.fillStyle = ink;
    ctx.textAlign = "center";
    for (let i = 0; curves && i * step <= span + 1e-9; i += 1) {
      const t = i * step;
      const x = Math.round(this.timeToX(t)) + 0.5;
      ctx.beginPath();
      ctx.moveTo(x, TOP_PX - 4);
      ctx.lineTo(x, lanesBottom);
      ctx.stroke();
      ctx.fillText(formatTime(t, step), x, lanesBottom + 12);
    }
    ctx.textAlign = "right";
    if (curves) ctx.fillText("time, s", width - RIGHT_PX, lanesBottom + 26);
    ctx.textAlign = "left";
    ctx.fillText(
      curves ? `peak gain ${formatNumber(peak, 4)} (lanes scaled to it)` : "no plan yet",
      LEFT_PX, TOP_PX / 2,
    );

    for (let c = 0; c < channels; c += 1) {
      const top = TOP_PX + c * (LANE_PX + LANE_GAP_PX);
      const bottom = top + LANE_PX;
      ctx.strokeStyle = grid;
      ctx.beginPath();
      ctx.moveTo(LEFT_PX, bottom + 0.5);
      ctx.lineTo(LEFT_PX + plotWidth, bottom + 0.5);
      ctx.stroke();
      const color = channelColor(c);
      ctx.fillStyle = color;
      ctx.textAlign = "right";
      ctx.font = "600 12px system-ui, sans-serif";
      ctx.fillText(this.labels[c] || String(c + 1), LEFT_PX - 10, top + LANE_PX / 2);
      ctx.font = "12px system-ui, sans-serif";
      if (!curves) continue;
      const y = (g) => bottom - g * scale * (LANE_PX - 2);
      ctx.beginPath();
      ctx.moveTo(this.timeToX(times[0]), bottom);
      times.forEach((t, i) => ctx.lineTo(this.timeToX(t), y(curves.gains[i][c])));
      ctx.lineTo(this.timeToX(times[times.length - 1]), bottom);
      ctx.closePath();
      ctx.globalAlpha = 0.18;
      ctx.fill();
      ctx.globalAlpha = 1;
      ctx.strokeStyle = color;
      ctx.lineWidth = 1.5;
      ctx.beginPath();
      times.forEach((t, i) => {
        const py = y(curves.gains[i][c]);
        if (i === 0) ctx.moveTo(this.timeToX(t), py);
        else ctx.lineTo(this.timeToX(t), py);
      });
      ctx.stroke();
      ctx.lineWidth = 1;
    }
    this.lanesBottom = lanesBottom;
  }

  paint() {
    if (!this.size) return;
    const ctx = this.canvas.getContext("2d");
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.clearRect(0, 0, this.canvas.width, this.canvas.height);
    ctx.drawImage(this.base, 0, 0);
    if (this.playheadS === null || !this.curves) return;
    const { ratio } = this.size;
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    const x = Math.round(this.timeToX(this.playheadS)) + 0.5;
    ctx.strokeStyle = getComputedStyle(this.canvas).getPropertyValue("--chart-playhead").trim()
      || "#0f172a";
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.moveTo(x, TOP_PX - 6);
    ctx.lineTo(x, this.lanesBottom);
    ctx.stroke();
  }
}

function formatTime(t, step) {
  const digits = step >= 1 ? 0 : step >= 0.1 ? 1 : 2;
  return t.toFixed(digits);
}
