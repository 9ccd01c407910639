// The armband drawn to scale as SVG, in centimetres: the forearm runs left (wrist, y = 0)
// to right (elbow); x, around the forearm, runs top to bottom. Pointer and keyboard input
// on it is reported in cm through callbacks; what to do with it is the caller's business.

import { channelColor, levelNorm } from "./units.js";

const SVG_NS = "http://www.w3.org/2000/svg";
const ACTUATOR_R_CM = 0.62;
const SKIN_MARGIN_CM = 1.0;
// Room around the band for the rulers and their titles, which grow on narrow screens.
const PAD = { left: 2.7, right: 1.6, top: 1.5, bottom: 2.0 };
const KEY_STEP_CM = 0.2;
const KEY_BIG_STEP_CM = 1.0;
const DRAW_MIN_STEP_CM = 0.12;
// Axis labels are sized in cm (the viewBox's unit) and grow when the armband is drawn so
// small that they would fall under this many CSS pixels (a 390 px phone).
const AXIS_LABEL_CM = 0.42;
const MIN_LABEL_PX = 11;

function el(name, attrs = {}, parent = null) {
  const node = document.createElementNS(SVG_NS, name);
  for (const [key, value] of Object.entries(attrs)) node.setAttribute(key, String(value));
  if (parent) parent.appendChild(node);
  return node;
}

function fmt(value) {
  return Number(value.toFixed(2)).toString();
}

export class Armband {
  // handlers: { down(id, pos), move(id, pos), up(id), drawn(points), addPoint(point) };
  // pos is {x_cm, y_cm}, a point [x_cm, y_cm]; both lie in the actuators' bounding box.
  // readout: an element that shows the position under the pointer or keyboard cursor.
  constructor(svg, handlers, readout) {
    this.svg = svg;
    this.readout = readout;
    this.handlers = handlers;
    this.mode = "live";
    this.actuators = [];
    this.pointers = new Map();
    this.stroke = null;
    this.keyboard = { x_cm: 0, y_cm: 0, down: false };
    this.display = [];
    svg.addEventListener("pointerdown", (e) => this.pointerDown(e));
    svg.addEventListener("pointermove", (e) => this.pointerMove(e));
    svg.addEventListener("pointerup", (e) => this.pointerUp(e));
    svg.addEventListener("pointercancel", (e) => this.pointerUp(e));
    svg.addEventListener("lostpointercapture", (e) => this.pointerUp(e));
    svg.addEventListener("pointerleave", () => this.showReadout(null));
    svg.addEventListener("keydown", (e) => this.keyDown(e));
    svg.addEventListener("focus", () => this.showCursor(svg.matches(":focus-visible")));
    svg.addEventListener("blur", () => this.blur());
    new ResizeObserver(() => this.scaleLabels()).observe(svg);
  }

  // --label-scale: how much the axis labels grow so that they stay readable.
  scaleLabels() {
    const box = this.svg.viewBox.baseVal;
    const widthPx = this.svg.getBoundingClientRect().width;
    if (!box || !box.width || !widthPx) return;
    const labelPx = AXIS_LABEL_CM * (widthPx / box.width);
    this.svg.style.setProperty("--label-scale", Math.max(1, MIN_LABEL_PX / labelPx).toFixed(3));
  }

  build(device) {
    const svg = this.svg;
    svg.replaceChildren();
    this.actuators = device.actuators.map((a, index) => ({ ...a, index, number: index + 1 }));
    const xs = this.actuators.map((a) => a.x_cm);
    const ys = this.actuators.map((a) => a.y_cm);
    this.bounds = {
      xMin: Math.min(...xs), xMax: Math.max(...xs), yMin: Math.min(...ys), yMax: Math.max(...ys),
    };
    const b = this.bounds;
    const left = b.yMin - SKIN_MARGIN_CM - PAD.left;
    const top = b.xMin - SKIN_MARGIN_CM - PAD.top;
    const width = b.yMax - b.yMin + 2 * SKIN_MARGIN_CM + PAD.left + PAD.right;
    const height = b.xMax - b.xMin + 2 * SKIN_MARGIN_CM + PAD.top + PAD.bottom;
    svg.setAttribute("viewBox", `${left} ${top} ${width} ${height}`);
    svg.setAttribute("preserveAspectRatio", "xMidYMid meet");
    svg.style.aspectRatio = `${width} / ${height}`;
    this.scaleLabels();

    // Ids of this picture's own gradient and marker: a page may hold two armbands.
    const glowId = `${svg.id}-glow`;
    const arrowId = `${svg.id}-arrow`;
    const defs = el("defs", {}, svg);
    const glow = el("radialGradient", { id: glowId }, defs);
    el("stop", { offset: "0%", "stop-color": "#f59e0b", "stop-opacity": 0.9 }, glow);
    el("stop", { offset: "55%", "stop-color": "#f59e0b", "stop-opacity": 0.35 }, glow);
    el("stop", { offset: "100%", "stop-color": "#f59e0b", "stop-opacity": 0 }, glow);
    const arrow = el("marker", {
      id: arrowId, viewBox: "0 0 10 10", refX: 6, refY: 5, markerWidth: 4, markerHeight: 4,
      orient: "auto-start-reverse",
    }, defs);
    el("path", { d: "M0,0 L10,5 L0,10 z", class: "path-arrow" }, arrow);

    el("rect", {
      class: "skin",
      x: b.yMin - SKIN_MARGIN_CM, y: b.xMin - SKIN_MARGIN_CM,
      width: b.yMax - b.yMin + 2 * SKIN_MARGIN_CM, height: b.xMax - b.xMin + 2 * SKIN_MARGIN_CM,
      rx: SKIN_MARGIN_CM, ry: SKIN_MARGIN_CM,
    }, svg);
    this.drawAxes(b);

    const mesh = el("g", { class: "triangles" }, svg);
    for (const triangle of device.triangles || []) {
      const points = triangle.map((i) => this.actuators[i]).map((a) => `${a.y_cm},${a.x_cm}`);
      el("polygon", { points: points.join(" ") }, mesh);
    }

    this.pathLayer = el("g", { class: "path-layer" }, svg);
    this.pathLine = el("polyline", { class: "plan-path", "marker-end": `url(#${arrowId})` },
      this.pathLayer);
    this.pathStart = el("circle", { class: "plan-start", r: 0.22, visibility: "hidden" },
      this.pathLayer);
    this.draft = el("polyline", { class: "draft-path" }, this.pathLayer);

    const actuatorLayer = el("g", { class: "actuators" }, svg);
    for (const a of this.actuators) {
      const g = el("g", {
        class: "actuator", transform: `translate(${a.y_cm} ${a.x_cm})`,
        "data-actuator": a.number, "data-channel": a.channel, "data-level": 0,
      }, actuatorLayer);
      a.halo = el("circle", {
        class: "halo", r: ACTUATOR_R_CM, fill: `url(#${glowId})`, opacity: 0,
      }, g);
      a.body = el("circle", { class: "body", r: ACTUATOR_R_CM }, g);
      a.fill = el("circle", { class: "fill", r: 0 }, g);
      el("circle", {
        class: "ring", r: ACTUATOR_R_CM, stroke: channelColor(a.channel - 1), fill: "none",
      }, g);
      const label = el("text", { class: "actuator-label", y: 0.02 }, g);
      label.textContent = String(a.number);
      const title = el("title", {}, g);
      title.textContent = `Actuator ${a.number} (channel ${a.channel}) at x ${fmt(a.x_cm)} cm, `
        + `y ${fmt(a.y_cm)} cm`;
      this.display.push(0);
    }

    this.playhead = el("circle", { class: "playhead", r: 0.3, visibility: "hidden" }, svg);
    this.contactLayer = el("g", { class: "contacts" }, svg);
    this.fingerLayer = el("g", { class: "fingers" }, svg);
    this.cursor = el("g", { class: "key-cursor", visibility: "hidden" }, svg);
    el("circle", { r: 0.45 }, this.cursor);
    el("path", { d: "M-0.75,0 H-0.25 M0.25,0 H0.75 M0,-0.75 V-0.25 M0,0.25 V0.75" }, this.cursor);
    this.keyboard = {
      x_cm: (b.xMin + b.xMax) / 2, y_cm: (b.yMin + b.yMax) / 2, down: false,
    };
    this.placeCursor();
  }

  drawAxes(b) {
    const svg = this.svg;
    const axes = el("g", { class: "axes" }, svg);
    const rulerY = b.xMax + SKIN_MARGIN_CM + 0.45;
    el("line", { x1: b.yMin, x2: b.yMax, y1: rulerY, y2: rulerY }, axes);
    const rows = [...new Set(this.actuators.map((a) => a.y_cm))].sort((p, q) => p - q);
    for (let y = Math.ceil(b.yMin); y <= b.yMax + 1e-9; y += 1) {
      el("line", { class: "minor", x1: y, x2: y, y1: rulerY, y2: rulerY + 0.18 }, axes);
    }
    for (const y of rows) {
      el("line", { x1: y, x2: y, y1: rulerY, y2: rulerY + 0.32 }, axes);
      const t = el("text", { x: y, y: rulerY + 0.85, class: "tick" }, axes);
      t.textContent = fmt(y);
    }
    const yTitle = el("text", { x: b.yMax + 0.55, y: rulerY + 0.1, class: "axis-title start" }, axes);
    yTitle.textContent = "y cm";

    const rulerX = b.yMin - SKIN_MARGIN_CM - 0.45;
    el("line", { x1: rulerX, x2: rulerX, y1: b.xMin, y2: b.xMax }, axes);
    const columns = [...new Set(this.actuators.map((a) => a.x_cm))].sort((p, q) => p - q);
    for (const x of columns) {
      el("line", { x1: rulerX - 0.32, x2: rulerX, y1: x, y2: x }, axes);
      const t = el("text", { x: rulerX - 0.45, y: x, class: "tick end" }, axes);
      t.textContent = fmt(x);
    }
    const xTitle = el("text", { x: rulerX - 0.45, y: b.xMin - 0.75, class: "axis-title end" }, axes);
    xTitle.textContent = "x cm";

    const endsY = b.xMin - SKIN_MARGIN_CM - 0.45;
    const wrist = el("text", { x: b.yMin - SKIN_MARGIN_CM + 0.2, y: endsY, class: "end-label start" },
      axes);
    wrist.textContent = "◂ wrist (hand)";
    const elbow = el("text", { x: b.yMax + SKIN_MARGIN_CM - 0.2, y: endsY, class: "end-label end" },
      axes);
    elbow.textContent = "elbow ▸";
  }

  setMode(mode) {
    this.mode = mode;
    this.svg.dataset.mode = mode;
    this.svg.setAttribute(
      "aria-label",
      mode === "live" ? "Armband: drag to touch" : "Armband: drag to draw a path",
    );
    if (mode !== "live") this.releaseAll();
  }

  // --- live levels, contacts and paths -----------------------------------------------

  setLevels(levels) {
    for (const a of this.actuators) {
      const level = Number(levels[a.channel - 1]) || 0;
      const target = levelNorm(level);
      const shown = Math.max(target, this.display[a.index] * 0.82);
      this.display[a.index] = shown < 0.01 ? 0 : shown;
      a.halo.setAttribute("r", fmt(ACTUATOR_R_CM * (1 + 1.6 * shown)));
      a.halo.setAttribute("opacity", fmt(Math.min(1, shown * 1.2)));
      a.fill.setAttribute("r", fmt(ACTUATOR_R_CM * shown));
      a.body.parentNode.dataset.level = String(level);
    }
  }

  // Light actuators by number (`lit`: the one under test) and outline others (`marked`:
  // the reference); numbers left out are shown plain.
  highlight({ lit = [], marked = [] } = {}) {
    for (const a of this.actuators) {
      const group = a.body.parentNode;
      group.classList.toggle("lit", lit.includes(a.number));
      group.classList.toggle("marked", marked.includes(a.number));
    }
  }

  setContacts(contacts) {
    const layer = this.contactLayer;
    while (layer.childElementCount > contacts.length) layer.lastChild.remove();
    contacts.forEach((c, i) => {
      let dot = layer.children[i];
      if (!dot) dot = el("circle", { class: "server-contact", r: 0.28 }, layer);
      dot.setAttribute("cx", fmt(c.y_cm));
      dot.setAttribute("cy", fmt(c.x_cm));
      dot.dataset.contact = c.contact;
      dot.classList.toggle("other", c.own === false);
    });
  }

  setPath(path) {
    // Drop repeated points (the fades hold the point still): the arrow at the end then
    // follows the last real segment.
    const points = (path || []).filter((p, i, all) => i === 0
      || Math.hypot(p[0] - all[i - 1][0], p[1] - all[i - 1][1]) > 1e-6);
    const shown = points.length > 0;
    this.pathLine.setAttribute(
      "points",
      shown ? points.map(([x, y]) => `${fmt(y)},${fmt(x)}`).join(" ") : "",
    );
    this.pathStart.setAttribute("visibility", shown ? "visible" : "hidden");
    if (shown) {
      this.pathStart.setAttribute("cx", fmt(points[0][1]));
      this.pathStart.setAttribute("cy", fmt(points[0][0]));
    }
  }

  setPlayhead(point) {
    this.playhead.setAttribute("visibility", point ? "visible" : "hidden");
    if (point) {
      this.playhead.setAttribute("cx", fmt(point[1]));
      this.playhead.setAttribute("cy", fmt(point[0]));
    }
  }

  // --- pointer input ---------------------------------------------------------------

  toCm(event) {
    const matrix = this.svg.getScreenCTM();
    if (!matrix) return null;
    const p = new DOMPoint(event.clientX, event.clientY).matrixTransform(matrix.inverse());
    return this.clamp({ x_cm: p.y, y_cm: p.x });
  }

  clamp({ x_cm, y_cm }) {
    const b = this.bounds;
    return {
      x_cm: Math.min(b.xMax, Math.max(b.xMin, x_cm)),
      y_cm: Math.min(b.yMax, Math.max(b.yMin, y_cm)),
    };
  }

  pointerDown(event) {
    if (!this.bounds || (event.pointerType === "mouse" && event.button !== 0)) return;
    event.preventDefault();
    this.svg.setPointerCapture(event.pointerId);
    const pos = this.toCm(event);
    if (!pos) return;
    if (this.mode === "draw") {
      this.stroke = { pointerId: event.pointerId, points: [[pos.x_cm, pos.y_cm]] };
      this.updateDraft();
      return;
    }
    const id = `p${event.pointerId}`;
    const finger = el("circle", { class: "finger", r: 0.42 }, this.fingerLayer);
    this.pointers.set(event.pointerId, { id, finger });
    this.placeFinger(finger, pos);
    this.handlers.down(id, pos);
  }

  pointerMove(event) {
    this.showReadout(this.toCm(event));
    if (this.mode === "draw") {
      if (!this.stroke || this.stroke.pointerId !== event.pointerId) return;
      const pos = this.toCm(event);
      const last = this.stroke.points[this.stroke.points.length - 1];
      if (pos && Math.hypot(pos.x_cm - last[0], pos.y_cm - last[1]) >= DRAW_MIN_STEP_CM) {
        this.stroke.points.push([pos.x_cm, pos.y_cm]);
        this.updateDraft();
      }
      return;
    }
    const pointer = this.pointers.get(event.pointerId);
    if (!pointer) return;
    const events = event.getCoalescedEvents ? event.getCoalescedEvents() : [];
    const pos = this.toCm(events.length ? events[events.length - 1] : event);
    if (!pos) return;
    this.placeFinger(pointer.finger, pos);
    this.handlers.move(pointer.id, pos);
  }

  pointerUp(event) {
    if (this.stroke && this.stroke.pointerId === event.pointerId) {
      const points = simplify(this.stroke.points, 0.04);
      this.stroke = null;
      this.draft.setAttribute("points", "");
      this.handlers.drawn(points);
      return;
    }
    const pointer = this.pointers.get(event.pointerId);
    if (!pointer) return;
    this.pointers.delete(event.pointerId);
    pointer.finger.remove();
    this.handlers.up(pointer.id);
  }

  releaseAll() {
    for (const [pointerId, pointer] of this.pointers) {
      pointer.finger.remove();
      this.handlers.up(pointer.id);
      if (this.svg.hasPointerCapture(pointerId)) this.svg.releasePointerCapture(pointerId);
    }
    this.pointers.clear();
    if (this.keyboard.down) this.keyboardLift();
  }

  showReadout(pos) {
    this.readout.textContent = pos ? `x ${pos.x_cm.toFixed(2)} cm, y ${pos.y_cm.toFixed(2)} cm` : "";
  }

  placeFinger(finger, pos) {
    finger.setAttribute("cx", fmt(pos.y_cm));
    finger.setAttribute("cy", fmt(pos.x_cm));
  }

  updateDraft() {
    this.draft.setAttribute(
      "points",
      this.stroke.points.map(([x, y]) => `${fmt(y)},${fmt(x)}`).join(" "),
    );
  }

  // --- keyboard input ----------------------------------------------------------------

  keyDown(event) {
    if (!this.bounds) return;
    const step = event.shiftKey ? KEY_BIG_STEP_CM : KEY_STEP_CM;
    const moves = {
      ArrowLeft: [0, -step], ArrowRight: [0, step], ArrowUp: [-step, 0], ArrowDown: [step, 0],
    };
    const k = this.keyboard;
    if (event.key in moves) {
      event.preventDefault();
      this.showCursor(true);
      const [dx, dy] = moves[event.key];
      Object.assign(k, this.clamp({ x_cm: k.x_cm + dx, y_cm: k.y_cm + dy }));
      this.placeCursor();
      this.showReadout(k);
      if (k.down) this.handlers.move("keyboard", { x_cm: k.x_cm, y_cm: k.y_cm });
    } else if (event.key === "Enter" || event.key === " ") {
      event.preventDefault();
      this.showCursor(true);
      if (event.repeat) return;
      if (this.mode === "draw") {
        this.handlers.addPoint([k.x_cm, k.y_cm]);
      } else if (k.down) {
        this.keyboardLift();
      } else {
        k.down = true;
        this.cursor.classList.add("pressed");
        this.handlers.down("keyboard", { x_cm: k.x_cm, y_cm: k.y_cm });
      }
    }
  }

  keyboardLift() {
    this.keyboard.down = false;
    this.cursor.classList.remove("pressed");
    this.handlers.up("keyboard");
  }

  showCursor(visible) {
    this.cursor.setAttribute("visibility", visible ? "visible" : "hidden");
  }

  blur() {
    this.showCursor(false);
    if (this.keyboard.down) this.keyboardLift();
  }

  placeCursor() {
    this.cursor.setAttribute("transform", `translate(${this.keyboard.y_cm} ${this.keyboard.x_cm})`);
  }
}

// Ramer-Douglas-Peucker: drop points closer than `toleranceCm` to the simplified line.
export function simplify(points, toleranceCm) {
  if (points.length < 3) return points.slice();
  const keep = new Array(points.length).fill(false);
  keep[0] = keep[points.length - 1] = true;
  const stack = [[0, points.length - 1]];
  while (stack.length) {
    const [first, last] = stack.pop();
    const [ax, ay] = points[first];
    const [bx, by] = points[last];
    const length = Math.hypot(bx - ax, by - ay);
    let worst = -1;
    let worstDistance = toleranceCm;
    for (let i = first + 1; i < last; i += 1) {
      const [px, py] = points[i];
      const distance = length === 0
        ? Math.hypot(px - ax, py - ay)
        : Math.abs((bx - ax) * (ay - py) - (ax - px) * (by - ay)) / length;
      if (distance > worstDistance) {
        worst = i;
        worstDistance = distance;
      }
    }
    if (worst > 0) {
      keep[worst] = true;
      stack.push([first, worst], [worst, last]);
    }
  }
  return points.filter((_, i) => keep[i]);
}
