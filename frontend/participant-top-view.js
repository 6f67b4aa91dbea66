// The 2D view: both tables seen from above as SVG, as the 3D view's camera sees them (Table B left, Table A
// right, the robot behind), each object drawn and labelled by name. It draws only when something changes: a
// still table, one placement glided from Table A to its place, or the step's recording (GET /me/top-view)
// played frame by frame. See docs/frontend.md.

import { pretty } from "./dom.js";

const SVG_NS = "http://www.w3.org/2000/svg";
const MM = 1000; // viewBox units per metre
const PAD = 0.05; // metres around the tables and the robot
const LABEL_PX = 14; // label text height on screen, whatever the view's size
const COLORS = { dinner_plate: "#ffffff", small_plate: "#f6d98b", bowl: "#3b82f6", knife: "#4b5563", fork: "#6b7280" };
const STACK = ["dinner_plate", "small_plate", "bowl", "knife", "fork"]; // lowest first when they share a place
const ROUND = ["plate", "bowl", "cup", "glass"]; // a study's own objects (layout kind): drawn as discs
const PLACE_SECONDS = 1.2; // a placement's glide in a demonstration

function svg(tag, attrs = {}, text = null) {
  const node = document.createElementNS(SVG_NS, tag);
  for (const [key, value] of Object.entries(attrs)) if (value !== null && value !== undefined) node.setAttribute(key, String(value));
  if (text !== null) node.textContent = text;
  return node;
}

/** Yaw (radians about the vertical) of a quaternion (w, x, y, z). */
export function quatYaw(w, x, y, z) {
  return Math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z));
}

/** Poses of a still table: the placed objects at their places on Table B (in order), the others where they start. */
export function restPoses(layout, placed) {
  const poses = {};
  for (const [name, o] of Object.entries(layout.objects)) {
    const at = placed.indexOf(name);
    poses[name] = at >= 0 ? { ...o.slot, z: 1 + at } : { ...o.start, z: 0 };
  }
  return poses;
}

/** The recorded motion's frames, [{t, poses}], t from 0 (seconds of the recording). */
export function motionFrames(motion, layout) {
  const t0 = motion.times[0] ?? 0;
  return motion.times.map((t, f) => {
    const poses = {};
    motion.bodies.forEach((body, b) => {
      const [x, y, z, yaw] = motion.poses[f][b];
      if (body in layout.objects) poses[body] = { x, y, z, yaw };
      else if (body === "hand") poses.hand = { x, y };
      else if (body === "forearm") poses.elbow = { x, y };
    });
    return { t: t - t0, poses };
  });
}

/** The SVG picture of the tables; `draw(poses)` moves the objects (and the arm when poses.hand is given). */
export function tablePicture(layout, { onPick = null } = {}) {
  const boxes = layout.tables.map((t) => [t.x - t.half_x, t.x + t.half_x, t.y - t.half_y, t.y + t.half_y]);
  const r = layout.robot;
  boxes.push([r.x - r.radius, r.x + r.radius, r.y - r.radius, r.y + r.radius]);
  const minX = Math.min(...boxes.map((b) => b[0])) - PAD;
  const maxX = Math.max(...boxes.map((b) => b[1])) + PAD + 0.05; // room for the tables' names
  const minY = Math.min(...boxes.map((b) => b[2])) - PAD;
  const maxY = Math.max(...boxes.map((b) => b[3])) + PAD;
  // From the 3D view's camera: screen right is world +y, screen down is world +x (towards the viewer).
  const px = (x, y) => [(y - minY) * MM, (x - minX) * MM];
  const width = (maxY - minY) * MM;
  const height = (maxX - minX) * MM;
  const root = svg("svg", { viewBox: `0 0 ${width.toFixed(0)} ${height.toFixed(0)}`, class: "top-picture",
    preserveAspectRatio: "xMidYMid meet", role: "img", "aria-labelledby": "top-view-desc" });
  const desc = svg("title", { id: "top-view-desc" }, "The tables from above");
  root.append(desc);
  for (const t of layout.tables) {
    const [x0, y0] = px(t.x - t.half_x, t.y - t.half_y);
    root.append(svg("rect", { x: x0, y: y0, width: 2 * t.half_y * MM, height: 2 * t.half_x * MM, rx: 14, class: "table-top" }));
  }
  const [rx, ry] = px(r.x, r.y);
  root.append(svg("circle", { cx: rx, cy: ry, r: r.radius * MM, class: "robot-base" }));
  const layer = svg("g", { class: "objects" });
  const arm = svg("polyline", { points: `${rx},${ry}`, class: "robot-arm" });
  const hand = svg("circle", { cx: rx, cy: ry, r: 22, class: "robot-hand" });
  const labels = svg("g", { class: "labels", "aria-hidden": "true" });
  root.append(layer, arm, hand, labels);
  const names = [];
  for (const t of layout.tables) {
    const [lx, ly] = px(t.x + t.half_x, t.y);
    names.push({ x: lx, y: ly + 8, text: t.name, table: true });
  }
  names.push({ x: rx + r.radius * MM, y: ry, text: "robot", table: true, right: true });

  const shapes = {};
  // The dinner objects in their stacking order; a study's own objects in theirs (they never share a place).
  const drawn = [...STACK.filter((n) => n in layout.objects), ...Object.keys(layout.objects).filter((n) => !STACK.includes(n))];
  for (const name of drawn) {
    const o = layout.objects[name];
    const g = svg("g", { class: `object object-${name}`, "data-object": name });
    const fill = o.colour || COLORS[name];
    if (o.kind ? ROUND.includes(o.kind) : o.shape === "disc") {
      const radius = (o.kind ? o.half_y : o.half_x) * MM; // a cup's handle makes it longer than it is wide
      g.append(svg("circle", { r: radius, fill }));
      if (o.kind ? o.kind === "plate" : name !== "bowl") g.append(svg("circle", { r: radius * 0.7, class: "rim" }));
    } else {
      g.append(svg("rect", { x: -o.half_x * MM, y: -Math.max(o.half_y * MM, 7), width: 2 * o.half_x * MM,
        height: Math.max(2 * o.half_y * MM, 14), rx: 6, fill }));
    }
    if (onPick) g.addEventListener("click", () => onPick(name));
    shapes[name] = g;
    layer.append(g);
  }

  let last = null;
  function draw(poses) {
    last = poses;
    const order = Object.keys(shapes).sort((a, b) => (poses[a]?.z ?? 0) - (poses[b]?.z ?? 0));
    for (const name of order) {
      const pose = poses[name];
      if (!pose) continue;
      const [x, y] = px(pose.x, pose.y);
      // A body's x axis along world yaw θ points at screen angle 90° - θ (the view swaps x and y).
      const degrees = 90 - (pose.yaw * 180) / Math.PI;
      shapes[name].setAttribute("transform", `translate(${x.toFixed(1)} ${y.toFixed(1)}) rotate(${degrees.toFixed(1)})`);
      layer.append(shapes[name]); // later (higher) objects on top
    }
    const shown = Boolean(poses.hand);
    if (shown) {
      const joints = [[rx, ry], poses.elbow ? px(poses.elbow.x, poses.elbow.y) : null, px(poses.hand.x, poses.hand.y)]
        .filter(Boolean);
      arm.setAttribute("points", joints.map(([x, y]) => `${x.toFixed(1)},${y.toFixed(1)}`).join(" "));
      hand.setAttribute("cx", joints.at(-1)[0].toFixed(1));
      hand.setAttribute("cy", joints.at(-1)[1].toFixed(1));
    }
    arm.style.display = hand.style.display = shown ? "" : "none";
    placeLabels(poses, order);
  }

  /** Every object's name on it, moved aside (below, above, right, left) where it would cover another name. */
  function placeLabels(poses, order) {
    const unitsPerPx = Math.max(width / Math.max(root.clientWidth, 1), height / Math.max(root.clientHeight, 1));
    const size = LABEL_PX * (Number.isFinite(unitsPerPx) && unitsPerPx > 0 ? unitsPerPx : 2);
    const taken = [];
    const box = (cx, cy, w) => [cx - w / 2 - size * 0.35, cy - size * 0.65, cx + w / 2 + size * 0.35, cy + size * 0.65];
    const free = (b) => taken.every((t) => b[2] <= t[0] || b[0] >= t[2] || b[3] <= t[1] || b[1] >= t[3]);
    const items = names.map((n) => ({ ...n, cy: n.right ? n.y : n.y + size * 0.6 }));
    for (const name of [...order].reverse()) { // the top object's name first
      const pose = poses[name];
      if (!pose) continue;
      const [x, y] = px(pose.x, pose.y);
      items.push({ x, cy: y, text: pretty(name), object: name });
    }
    labels.replaceChildren();
    for (const item of items) {
      const w = item.text.length * size * 0.58;
      if (item.right) item.x += w / 2 + size * 0.5; // beside the robot's base
      // Beside as well as below and above: ten objects on a phone's small table leave no free row for some names.
      const tries = item.object ? [0, 1.3, -1.3, 2.6, -2.6, 3.9].map((k) => [item.x, item.cy + k * size])
        .concat([0, 1.3, -1.3].flatMap((k) => [1, -1].map((s) => [item.x + s * (w + size), item.cy + k * size])))
        : [[item.x, item.cy]];
      const inside = (x) => Math.min(Math.max(x, w / 2 + size * 0.4), width - w / 2 - size * 0.4); // within the picture
      const [cx, cy] = (tries.find(([tx, ty]) => free(box(inside(tx), ty, w))) ?? tries[0]).map((v, i) => (i ? v : inside(v)));
      const b = box(cx, cy, w);
      taken.push(b);
      const g = svg("g", { class: item.table ? "label table-label" : "label", "data-label": item.object ?? item.text });
      if (!item.table) g.append(svg("rect", { x: b[0], y: b[1], width: b[2] - b[0], height: b[3] - b[1], rx: size * 0.25 }));
      g.append(svg("text", { x: cx, y: cy, "font-size": size.toFixed(1), "text-anchor": "middle", "dominant-baseline": "central" }, item.text));
      labels.append(g);
    }
  }

  const resize = new ResizeObserver(() => { if (last) placeLabels(last, Object.keys(shapes).sort((a, b) => (last[a]?.z ?? 0) - (last[b]?.z ?? 0))); });
  resize.observe(root);
  return { element: root, draw, describe: (text) => { desc.textContent = text; } };
}

const ease = (a) => a * a * (3 - 2 * a);

/** The 2D view's player: a still table, a glided placement, or a recording played over `seconds`; it animates
 * only while something moves (requestAnimationFrame), and tells how far a recording has been shown. */
export class TopViewPlayer {
  constructor(picture) {
    this.picture = picture;
    this.frames = null;
    this.duration = 0; // seconds the recording plays
    this.position = 0; // seconds of it shown so far
    this.frameId = null;
  }

  /** Show a still table (stopping whatever moved). */
  still(poses) {
    this.stop();
    this.frames = null;
    this.picture.draw(poses);
  }

  /** Glide `obj` from `from` (still poses) to where `to` has it, the hand carrying it. */
  place(obj, from, to) {
    this.stop();
    this.frames = null;
    const start = performance.now();
    const step = (now) => {
      const a = Math.min(1, (now - start) / (PLACE_SECONDS * 1000));
      const e = ease(a);
      const p = from[obj];
      const q = to[obj];
      const moving = { x: p.x + (q.x - p.x) * e, y: p.y + (q.y - p.y) * e, yaw: p.yaw + (q.yaw - p.yaw) * e, z: 99 };
      this.picture.draw(a < 1 ? { ...from, [obj]: moving, hand: moving } : to);
      this.frameId = a < 1 ? requestAnimationFrame(step) : null;
    };
    this.frameId = requestAnimationFrame(step);
  }

  /** Play recorded frames over `seconds` from `from` (a fraction of it; 0: the start), or show the end at once
   * with `atEnd`. */
  play(frames, seconds, { atEnd = false, from = 0 } = {}) {
    this.stop();
    this.frames = frames;
    const span = frames.at(-1)?.t || 0;
    this.duration = seconds > 0 ? seconds : span;
    this.rate = this.duration > 0 ? span / this.duration : 1;
    this.position = atEnd ? this.duration : Math.min(1, Math.max(0, from)) * this.duration;
    this.show(this.position);
    if (atEnd || this.duration <= 0) return;
    let last = null;
    const step = (now) => {
      if (last !== null) this.position = Math.min(this.duration, this.position + (now - last) / 1000);
      last = now;
      this.show(this.position);
      this.frameId = this.position < this.duration && this.picture.element.isConnected ? requestAnimationFrame(step) : null;
    };
    this.frameId = requestAnimationFrame(step);
  }

  /** Whether a recording is loaded and how much of it was shown (0-1). */
  get fraction() {
    return this.frames && this.duration > 0 ? this.position / this.duration : null;
  }

  show(seconds) {
    const t = seconds * this.rate;
    const frames = this.frames;
    let lo = 0;
    let hi = frames.length - 1;
    while (lo < hi) { const mid = (lo + hi + 1) >> 1; if (frames[mid].t <= t) lo = mid; else hi = mid - 1; }
    this.picture.draw(frames[lo].poses);
  }

  stop() {
    if (this.frameId !== null) cancelAnimationFrame(this.frameId);
    this.frameId = null;
  }
}
