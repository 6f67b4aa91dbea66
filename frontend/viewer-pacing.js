// Paces viser's 3D client in the participant's copy of its page (inlined first in its <head>, before viser's own
// script). viser 1.1 draws on demand, but a heartbeat redraws every second, each change keeps drawing for 250 ms,
// and its recording player re-renders its playback bar 120 times a second, held pose or not; with software WebGL
// a frame costs a tenth of a second or more, so a view with nothing moving used a third to a half of a core.
// Here: frames at the screen's rate for a moment after the participant's input, at a capped rate otherwise (the
// robot moving, a recording playing), the heartbeat's redraw only every IDLE_FRAME_MS, and the player's clock
// at the capped rate while it shows motion, 4 times a second while it holds a pose.
(() => {
  const params = new URLSearchParams(location.search);
  const off = params.get("pacing") === "off"; // viser's own pace, frames still counted (the benchmarks compare)
  const nativeFrame = window.requestAnimationFrame.bind(window);
  const software = params.has("fixedDpr"); // the page asks for it on software WebGL
  const INPUT_MS = 1000; // after a pointer, wheel, touch or key event, every frame (orbiting the camera)
  const CAPPED_FRAME_MS = software ? 100 : 33; // otherwise at most 10 (software) or 30 frames a second
  const IDLE_FRAME_MS = 60000; // the heartbeat's safety redraw
  const HEARTBEAT_MS = 1000; // viser's heartbeat interval (a constant in its client)
  const PLAYER_TICK_MS = 1000 / 120; // viser's recording player advances its clock this often (also a constant)
  const STILL_MS = 1000; // no frame asked for this long: nothing moves
  const STILL_TICK_MS = 250; // the player's clock then (the participant page reads its slider every 250 ms)
  const stats = { frames: 0, busyMs: 0, heartbeats: 0, skipped: 0, playerTicks: 0 }; // for the benchmarks
  const held = new Map();
  let nextId = 1;
  let inputUntil = 0;
  let lastFrame = -Infinity;
  let timer = null;
  let pending = false;
  let askedAt = 0; // when the pending frame was asked of the browser
  let latency = 0; // how long the browser took to run the last one asked for (vsync, a frame still drawing): ask
  // that much earlier, up to half the cap
  let lastAsked = -Infinity; // when a frame was last asked for
  let heartbeatRunning = false; // inside a 1 s interval's callback
  let heartbeatAsked = false; // and it asked for a frame

  function run(time) {
    pending = false;
    lastFrame = performance.now();
    latency = Math.min(lastFrame - askedAt, CAPPED_FRAME_MS / 2);
    const callbacks = [...held.values()];
    held.clear();
    stats.frames += 1;
    for (const callback of callbacks) {
      try { callback(time); } catch (error) { setTimeout(() => { throw error; }); }
    }
    stats.busyMs += performance.now() - lastFrame;
  }

  function schedule() {
    if (pending || held.size === 0) return;
    const now = performance.now();
    const wait = off || now < inputUntil ? 0 : lastFrame + CAPPED_FRAME_MS - latency - now;
    if (wait <= 0) {
      pending = true;
      askedAt = now;
      nativeFrame(run);
    } else if (timer === null) {
      timer = setTimeout(() => { timer = null; schedule(); }, wait);
    }
  }

  window.requestAnimationFrame = (callback) => {
    const id = nextId++;
    held.set(id, callback);
    lastAsked = performance.now();
    if (heartbeatRunning) heartbeatAsked = true;
    schedule();
    return id;
  };
  window.cancelAnimationFrame = (id) => { held.delete(id); };

  // Input: frames at the screen's rate at once (a frame already waiting for the cap goes now). A pointer moving
  // with no button pressed only hovers: its highlight comes at the capped rate.
  const onInput = (event) => {
    if (event.type === "pointermove" && event.buttons === 0) return;
    inputUntil = performance.now() + INPUT_MS;
    if (timer !== null) { clearTimeout(timer); timer = null; }
    schedule();
  };
  for (const type of ["pointerdown", "pointermove", "pointerup", "wheel", "touchstart", "touchmove", "keydown",
    "resize"]) {
    window.addEventListener(type, onInput, { capture: true, passive: true });
  }

  // viser's heartbeat is a 1 s interval that asks for a frame; its reconnection retry is a 1 s interval that does
  // not. A 1 s interval whose callback asked for a frame is the heartbeat: it runs every IDLE_FRAME_MS from then on.
  const nativeInterval = window.setInterval.bind(window);
  window.setInterval = (callback, delay, ...args) => {
    if (off || typeof callback !== "function") return nativeInterval(callback, delay, ...args);
    if (Number(delay) === PLAYER_TICK_MS) return nativeInterval(playerTick(callback, args), delay);
    if (Number(delay) !== HEARTBEAT_MS) return nativeInterval(callback, delay, ...args);
    let heartbeat = false;
    let lastRun = -Infinity;
    return nativeInterval(() => {
      const now = performance.now();
      if (heartbeat && now - lastRun < IDLE_FRAME_MS) { stats.skipped += 1; return; }
      lastRun = now;
      heartbeatRunning = true;
      heartbeatAsked = false;
      try {
        callback(...args);
      } finally {
        heartbeatRunning = false;
        if (heartbeatAsked && !heartbeat) heartbeat = true;
        if (heartbeat) stats.heartbeats += 1;
      }
    }, delay);
  };

  // The player measures the time between its own ticks (Date.now), so fewer ticks play the recording at the same
  // speed: each applies what came due since the one before.
  function playerTick(callback, args) {
    let last = -Infinity;
    return () => {
      const now = performance.now();
      if (now - last < (now - lastAsked < STILL_MS ? CAPPED_FRAME_MS : STILL_TICK_MS)) return;
      last = now;
      stats.playerTicks += 1;
      callback(...args);
    };
  }

  window.tableteachPacing = stats;
})();
