// Inline-SVG drawing for the dashboard: line charts and the top-down view of the tables. No library.

const SVG_NS = "http://www.w3.org/2000/svg";

/** An SVG element with attributes (and optional text). */
export function svg(tag, attrs = {}, text = null) {
  const el = document.createElementNS(SVG_NS, tag);
  for (const [key, value] of Object.entries(attrs)) {
    if (value !== null && value !== undefined) el.setAttribute(key, String(value));
  }
  if (text !== null) el.textContent = text;
  return el;
}

/** Round, readable tick values covering [lo, hi]. */
export function ticks(lo, hi, count = 5) {
  if (!(hi > lo)) return [lo];
  const step = tickStep(lo, hi, count);
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(+v.toFixed(10));
  return out;
}

/** The round step between about `count` ticks over [lo, hi]. */
export function tickStep(lo, hi, count) {
  const raw = Math.max(hi - lo, 1e-12) / count;
  const magnitude = 10 ** Math.floor(Math.log10(raw));
  return [1, 2, 2.5, 5, 10].map((m) => m * magnitude).find((s) => s >= raw - 1e-12);
}

export const PALETTE = ["#2563eb", "#d97706", "#059669", "#7c3aed", "#dc2626", "#0891b2"];

/**
 * A line chart as an <svg> element.
 * series: [{name, color, points: [{x, y, label?}], faint?, dashed?, band?: [{x, lo, hi}]}]; null y values break the line.
 * options: {title, xLabel, yLabel, yMin, yMax, xMin, xMax, width, height, integerX, format}
 */
export function lineChart(series, options = {}) {
  const width = options.width ?? 420;
  const height = options.height ?? 240;
  const legend = options.legend === false ? [] : series.filter((s) => !s.faint && s.name);
  // Title on the first line, legend on the second (right-aligned): neither ever covers the data.
  const legendY = options.title ? 32 : 12;
  const margin = { top: legend.length ? legendY + 12 : options.title ? 28 : 12, right: 14,
    bottom: options.xLabel ? 36 : 22, left: options.yLabel ? 50 : 38 };
  const plotW = width - margin.left - margin.right;
  const plotH = height - margin.top - margin.bottom;
  const all = series.flatMap((s) => s.points.filter((p) => p.y !== null && p.y !== undefined));
  const xs = all.map((p) => p.x);
  const ys = all.map((p) => p.y);
  const xMin = options.xMin ?? Math.min(0, ...xs);
  const xMax = Math.max(options.xMax ?? -Infinity, ...xs, xMin + 1);
  const yMin = options.yMin ?? Math.min(0, ...ys);
  let yMax = options.yMax ?? Math.max(...ys, yMin + 1e-9);
  if (options.yMax === undefined) {
    const step = tickStep(yMin, yMax, 4);
    yMax = Math.ceil(yMax / step - 1e-9) * step; // the top gridline is at or above every value
  }
  const fmt = options.format ?? ((v) => v.toFixed(2));
  const yStep = tickStep(yMin, yMax, 4);
  let yDecimals = 0;
  while (yDecimals < 4 && Math.abs(yStep * 10 ** yDecimals - Math.round(yStep * 10 ** yDecimals)) > 1e-9) yDecimals += 1;
  const fmtTick = (v) => v.toFixed(yDecimals);
  const sx = (x) => margin.left + ((x - xMin) / (xMax - xMin)) * plotW;
  const sy = (y) => margin.top + plotH - ((y - yMin) / (yMax - yMin)) * plotH;

  const root = svg("svg", { viewBox: `0 0 ${width} ${height}`, class: "chart", role: "img",
    "aria-label": options.title ?? options.yLabel ?? "chart" });
  if (options.title) root.append(svg("text", { x: 4, y: 15, class: "chart-title" }, options.title));

  const yTicks = ticks(yMin, yMax, 4);
  for (const t of yTicks) {
    root.append(svg("line", { x1: margin.left, x2: margin.left + plotW, y1: sy(t), y2: sy(t), class: "grid" }));
    root.append(svg("text", { x: margin.left - 6, y: sy(t) + 4, class: "tick", "text-anchor": "end" }, fmtTick(t)));
  }
  let xTicks = ticks(xMin, xMax, Math.min(8, xMax - xMin));
  if (options.integerX !== false) xTicks = xTicks.filter((t) => Number.isInteger(t));
  for (const t of xTicks) {
    root.append(svg("line", { x1: sx(t), x2: sx(t), y1: margin.top + plotH, y2: margin.top + plotH + 4, class: "axis" }));
    root.append(svg("text", { x: sx(t), y: margin.top + plotH + 16, class: "tick", "text-anchor": "middle" }, String(t)));
  }
  root.append(svg("line", { x1: margin.left, x2: margin.left + plotW, y1: margin.top + plotH, y2: margin.top + plotH, class: "axis" }));
  root.append(svg("line", { x1: margin.left, x2: margin.left, y1: margin.top, y2: margin.top + plotH, class: "axis" }));
  if (options.xLabel) {
    root.append(svg("text", { x: margin.left + plotW / 2, y: height - 6, class: "axis-label", "text-anchor": "middle" }, options.xLabel));
  }
  if (options.yLabel) {
    root.append(svg("text", { x: 12, y: margin.top + plotH / 2, class: "axis-label", "text-anchor": "middle",
      transform: `rotate(-90 12 ${margin.top + plotH / 2})` }, options.yLabel));
  }

  for (const s of series) {
    if (s.band) {
      const band = s.band.filter((b) => b.lo !== null && b.hi !== null);
      if (band.length > 1) {
        const d = band.map((b, i) => `${i ? "L" : "M"}${sx(b.x)},${sy(b.hi)}`).join("")
          + band.slice().reverse().map((b) => `L${sx(b.x)},${sy(b.lo)}`).join("") + "Z";
        root.append(svg("path", { d, fill: s.color, class: "band" }));
      }
    }
    let d = "";
    let pen = false;
    for (const p of s.points) {
      if (p.y === null || p.y === undefined) { pen = false; continue; }
      d += `${pen ? "L" : "M"}${sx(p.x).toFixed(1)},${sy(p.y).toFixed(1)}`;
      pen = true;
    }
    const cls = ["series", s.faint ? "faint" : "", s.dashed ? "dashed" : ""].join(" ").trim();
    root.append(svg("path", { d, stroke: s.color, class: cls, "data-series": s.name }));
    if (!s.faint) {
      for (const p of s.points) {
        if (p.y === null || p.y === undefined) continue;
        const dot = svg("circle", { cx: sx(p.x), cy: sy(p.y), r: 3.2, fill: s.color, class: "dot" });
        dot.append(svg("title", {}, p.label ?? `${s.name}: ${fmt(p.y)} at ${p.x}`));
        root.append(dot);
      }
    }
  }

  // Legend on the title line, right-aligned, so it never covers the data.
  let right = width - margin.right;
  for (const s of legend.slice().reverse()) {
    right -= s.name.length * 6 + 4;
    root.append(svg("text", { x: right, y: legendY + 4, class: "legend" }, s.name));
    root.append(svg("line", { x1: right - 20, x2: right - 4, y1: legendY, y2: legendY, stroke: s.color,
      class: `legend-line ${s.dashed ? "dashed" : ""}` }));
    right -= 30;
  }
  return root;
}

// ---------------------------------------------------------------- top-down view of the tables

const OBJECT_COLORS = {
  dinner_plate: "#f8fafc", small_plate: "#fef3c7", bowl: "#3b82f6", knife: "#6b7280", fork: "#9ca3af",
};
const STACK = ["dinner_plate", "small_plate", "bowl", "knife", "fork"];
const ROUND = ["plate", "bowl", "cup", "glass"]; // a study's own objects (layout kind) drawn as discs

/** Yaw (rotation about z, radians) of a quaternion (w, x, y, z). */
export function quatYaw(w, x, y, z) {
  return Math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z));
}

/**
 * The tables seen from above as an <svg>; returns {element, draw(poses)} where poses maps each
 * object to {x, y, yaw, z?, placed?} in metres (world frame), and hand and elbow (optional) to {x, y}.
 */
export function tableView(layout, { width = 560, height = 420 } = {}) {
  const boxes = layout.tables.map((t) => [t.x - t.half_x, t.x + t.half_x, t.y - t.half_y, t.y + t.half_y]);
  boxes.push([layout.robot.x - layout.robot.radius, layout.robot.x + layout.robot.radius,
    layout.robot.y - layout.robot.radius, layout.robot.y + layout.robot.radius]);
  const pad = 0.04;
  const minX = Math.min(...boxes.map((b) => b[0])) - pad;
  const maxX = Math.max(...boxes.map((b) => b[1])) + pad;
  const minY = Math.min(...boxes.map((b) => b[2])) - pad;
  const maxY = Math.max(...boxes.map((b) => b[3])) + pad;
  // Seen from above, looking along the robot's +x: up on screen is +x, right is -y (Table B on the right).
  const scale = Math.min(width / (maxY - minY), height / (maxX - minX));
  const offsetX = (width - (maxY - minY) * scale) / 2;
  const offsetY = (height - (maxX - minX) * scale) / 2;
  const px = (x, y) => [(maxY - y) * scale + offsetX, (maxX - x) * scale + offsetY];
  const root = svg("svg", { viewBox: `0 0 ${width} ${height}`, class: "table-view", role: "img", "aria-label": "top-down replay" });
  root.append(svg("rect", { x: 0, y: 0, width, height, class: "floor" }));
  for (const t of layout.tables) {
    const [x0, y0] = px(t.x + t.half_x, t.y + t.half_y);
    const [x1, y1] = px(t.x - t.half_x, t.y - t.half_y);
    root.append(svg("rect", { x: Math.min(x0, x1), y: Math.min(y0, y1), width: Math.abs(x1 - x0), height: Math.abs(y1 - y0), rx: 6, class: "table-top" }));
    const [lx, ly] = px(t.x - t.half_x, t.y);
    root.append(svg("text", { x: lx, y: ly + 16, class: "table-name", "text-anchor": "middle" }, t.name));
  }
  for (const [name, o] of Object.entries(layout.objects)) {
    root.append(objectShape(name, o, scale, "slot", px(o.slot.x, o.slot.y), o.slot.yaw));
  }
  const [rx, ry] = px(layout.robot.x, layout.robot.y);
  root.append(svg("circle", { cx: rx, cy: ry, r: layout.robot.radius * scale, class: "robot-base" }));
  root.append(svg("text", { x: rx, y: ry + layout.robot.radius * scale + 14, class: "table-name", "text-anchor": "middle" }, "robot"));
  const arm = svg("polyline", { points: `${rx},${ry}`, class: "robot-arm" });
  const hand = svg("circle", { cx: rx, cy: ry, r: 6, class: "robot-hand" });
  const layer = svg("g", { class: "objects" });
  root.append(layer, arm, hand);
  const shapes = {};
  // The dinner objects in their stacking order, then a study's own objects (they never share a place).
  const drawn = [...STACK.filter((n) => n in layout.objects), ...Object.keys(layout.objects).filter((n) => !STACK.includes(n))];
  for (const name of drawn) {
    shapes[name] = objectShape(name, layout.objects[name], scale, "object", [0, 0], 0);
    shapes[name].setAttribute("data-object", name);
    layer.append(shapes[name]);
  }

  function draw(poses) {
    const order = Object.keys(shapes).sort((a, b) => (poses[a]?.z ?? 0) - (poses[b]?.z ?? 0));
    for (const name of order) {
      const pose = poses[name];
      if (!pose) continue;
      const [x, y] = px(pose.x, pose.y);
      // Screen rotation: world yaw is counter-clockwise about +z; the view maps x to up and y to left.
      const degrees = -(pose.yaw * 180) / Math.PI - 90;
      shapes[name].setAttribute("transform", `translate(${x.toFixed(1)} ${y.toFixed(1)}) rotate(${degrees.toFixed(1)})`);
      shapes[name].classList.toggle("placed", Boolean(pose.placed));
      layer.append(shapes[name]); // re-append: later (higher) objects are drawn on top
    }
    if (poses.hand) {
      const [hx, hy] = px(poses.hand.x, poses.hand.y);
      const joints = [[rx, ry], poses.elbow ? px(poses.elbow.x, poses.elbow.y) : null, [hx, hy]].filter(Boolean);
      arm.setAttribute("points", joints.map(([x, y]) => `${x.toFixed(1)},${y.toFixed(1)}`).join(" "));
      hand.setAttribute("cx", hx.toFixed(1));
      hand.setAttribute("cy", hy.toFixed(1));
    }
    arm.style.display = hand.style.display = poses.hand ? "" : "none";
  }
  return { element: root, draw };
}

function objectShape(name, o, scale, cls, [x, y], yaw) {
  const g = svg("g", { class: `${cls} ${cls}-${name}` });
  if (cls === "slot") g.setAttribute("transform", `translate(${x} ${y}) rotate(${-(yaw * 180) / Math.PI - 90})`);
  const fill = cls === "slot" ? "none" : o.colour || OBJECT_COLORS[name];
  if (o.kind ? ROUND.includes(o.kind) : o.shape === "disc") {
    const radius = (o.kind ? o.half_y : o.half_x) * scale; // a cup's handle makes it longer than it is wide
    g.append(svg("circle", { cx: 0, cy: 0, r: radius, fill }));
    if (cls !== "slot" && (o.kind ? o.kind === "plate" : name !== "bowl")) g.append(svg("circle", { cx: 0, cy: 0, r: radius * 0.72, class: "rim" }));
  } else {
    g.append(svg("rect", { x: -o.half_x * scale, y: -o.half_y * scale, width: 2 * o.half_x * scale,
      height: Math.max(2 * o.half_y * scale, 3), rx: 2, fill }));
  }
  if (cls !== "slot") g.append(svg("title", {}, name.replaceAll("_", " ")));
  return g;
}
