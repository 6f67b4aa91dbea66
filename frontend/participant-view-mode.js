// Which view the participant page shows, 3D or 2D: the participant's own choice (kept in this browser), else 2D
// when the browser has no WebGL, else 3D, switched to 2D when the page is measured too slow while the 3D view
// is shown (software WebGL can block the page for seconds). Also: whether the 3D renderer is software, so the
// 3D view is drawn at a lower resolution. See docs/frontend.md.

const CHOICE_KEY = "tableteach-view";
const SOFTWARE = /swiftshader|llvmpipe|softpipe|software|basic render/i;
export const SOFTWARE_DPR = 0.5; // viser's fixedDpr for a software renderer: a quarter of the pixels to draw
const LAG_TICK_MS = 250;
const STALL_MS = 5000; // the page did not run its timers for this long: a stall (issue 21 measured 5 to 80 s)
const STALLS_TO_SWITCH = 2; // this many stalls within STALL_WINDOW_MS while the 3D view is shown: too slow
const STALL_WINDOW_MS = 60000;

/** What this browser's WebGL is: {webgl: bool, software: bool, renderer: string}. */
export function probeWebgl() {
  try {
    const canvas = document.createElement("canvas");
    const gl = canvas.getContext("webgl2") || canvas.getContext("webgl");
    if (!gl) return { webgl: false, software: false, renderer: "" };
    const info = gl.getExtension("WEBGL_debug_renderer_info");
    const renderer = String(info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER));
    gl.getExtension("WEBGL_lose_context")?.loseContext();
    return { webgl: true, software: SOFTWARE.test(renderer), renderer };
  } catch {
    return { webgl: false, software: false, renderer: "" };
  }
}

/** The participant's stored choice, "2d", "3d" or null. */
export function storedChoice() {
  try {
    const value = localStorage.getItem(CHOICE_KEY);
    return value === "2d" || value === "3d" ? value : null;
  } catch {
    return null;
  }
}

export function storeChoice(mode) {
  try { localStorage.setItem(CHOICE_KEY, mode); } catch { /* private mode: the choice lasts for this page */ }
}

/** The view to start with, and why: {mode, reason} (reason: "choice", "no-webgl" or "default"). */
export function initialMode(probe) {
  if (!probe.webgl) return { mode: "2d", reason: "no-webgl" };
  const choice = storedChoice();
  return choice ? { mode: choice, reason: "choice" } : { mode: "3d", reason: "default" };
}

/** The 3D viewer's address with the resolution lowered for a software renderer (viser's fixedDpr parameter). */
export function viewerUrl(url, probe) {
  if (!url || !probe.software) return url;
  return `${url}${url.includes("?") ? "&" : "?"}fixedDpr=${SOFTWARE_DPR}`;
}

/** Watch the page's responsiveness; `onSlow()` once it stalled STALLS_TO_SWITCH times while `active()` held. */
export function watchStalls(active, onSlow) {
  let last = performance.now();
  let stalls = [];
  // A background tab's timers are slowed: a gap that spans a hidden stretch is not a stall.
  document.addEventListener("visibilitychange", () => { last = performance.now(); });
  const timer = setInterval(() => {
    const now = performance.now();
    const gap = now - last;
    last = now;
    if (document.visibilityState === "hidden") return;
    if (!active()) { stalls = []; return; }
    if (gap < STALL_MS) return;
    stalls = [...stalls.filter((t) => now - t < STALL_WINDOW_MS), now];
    if (stalls.length >= STALLS_TO_SWITCH) {
      clearInterval(timer);
      onSlow();
    }
  }, LAG_TICK_MS);
  return () => clearInterval(timer);
}
