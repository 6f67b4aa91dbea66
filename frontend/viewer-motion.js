// Plays the robot's placement motions in the participant's copy of viser's client page (inlined in its <head>,
// before viser's own script). The server sends each placement once (backend/sim/motion_message.py) rather than
// streaming 30 pose frames a second; this script takes it out of the message batches viser's websocket worker
// hands the page and, on the page's own clock, hands viser the SetPositionMessage/SetOrientationMessage batches the
// server used to stream. A motion still playing when the server moves one of its bodies, or sends the next motion,
// jumps to its last frame first: the server's scene assumes the browser holds it.
(() => {
  const MOTION = "TableTeachMotionMessage";
  const POSES = new Set(["SetPositionMessage", "SetOrientationMessage"]);
  const stats = { motions: 0, frames: 0, cut: 0 }; // for the tests and the benchmarks
  let playing = null;

  const floats = (bytes) => new Float32Array(bytes.slice().buffer); // msgpack's bin may sit unaligned

  /** A motion message as the player keeps it: its nodes, owner, float32 times and poses, and where it is. */
  function start(message) {
    const times = floats(message.times);
    return { names: message.nodes, nodes: new Set(message.nodes), owner: message.owner, times,
      poses: floats(message.poses), count: times.length, frame: -1, startedAt: performance.now(), sent: null };
  }

  /** The pose messages that show frame `frame` of a motion (bodies that did not move since the last one shown are
   * left out). */
  function frameMessages(motion, frame) {
    const out = [];
    const n = motion.names.length;
    const p = motion.poses;
    for (let k = 0; k < n; k++) {
      const at = (frame * n + k) * 7;
      const last = motion.sent === null ? -1 : (motion.sent * n + k) * 7;
      let moved = last < 0;
      for (let i = 0; i < 7 && !moved; i++) moved = p[at + i] !== p[last + i];
      if (!moved) continue;
      const name = motion.names[k];
      out.push({ type: "SetPositionMessage", name, position: [p[at], p[at + 1], p[at + 2]], owner: motion.owner });
      out.push({ type: "SetOrientationMessage", name, wxyz: [p[at + 3], p[at + 4], p[at + 5], p[at + 6]],
        owner: motion.owner });
    }
    motion.sent = frame;
    motion.frame = frame;
    stats.frames += 1;
    return out;
  }

  /** The frame due now (the last one whose time has come). */
  function dueFrame(motion) {
    const elapsed = (performance.now() - motion.startedAt) / 1000;
    let frame = Math.max(motion.frame, 0);
    while (frame + 1 < motion.count && motion.times[frame + 1] <= elapsed) frame += 1;
    return frame;
  }

  /** Jump the playing motion to its last frame and stop it (its pose messages go to `out`). */
  function cut(out) {
    out.push(...frameMessages(playing, playing.count - 1));
    playing = null;
    stats.cut += 1;
  }

  /** Start playing a motion: its first frame goes to `out`, the others to `deliver` as their times come. */
  function play(message, out, deliver) {
    const motion = start(message);
    stats.motions += 1;
    out.push(...frameMessages(motion, 0));
    if (motion.count < 2) return;
    playing = motion;
    const tick = () => {
      if (playing !== motion) return;
      const frame = dueFrame(motion);
      if (frame !== motion.frame) deliver(frameMessages(motion, frame));
      if (frame + 1 >= motion.count) playing = null;
      else requestAnimationFrame(tick);
    };
    requestAnimationFrame(tick);
  }

  /** A worker's messages to viser with the motions taken out and played; `deliver` hands viser a batch. */
  function route(data, deliver) {
    if (data?.type === "connected") playing = null; // viser resets its scene: the server sends it whole again
    if (data?.type !== "message_batch" || !Array.isArray(data.messages)) return;
    const out = [];
    for (const message of data.messages) {
      const motion = message?.type === MOTION;
      if (playing && (motion || (POSES.has(message?.type) && playing.nodes.has(message.name)))) cut(out);
      if (motion) play(message, out, deliver);
      else out.push(message);
    }
    data.messages = out;
  }

  // viser's websocket runs in a worker and hands the page batches through worker.onmessage: every worker the page
  // makes passes its messages through route() first.
  const NativeWorker = window.Worker;
  if (typeof NativeWorker === "function") {
    window.Worker = class extends NativeWorker {
      constructor(...args) {
        super(...args);
        let handler = null;
        Object.defineProperty(this, "onmessage", {
          configurable: true,
          get: () => handler,
          set: (fn) => { handler = fn; },
        });
        this.addEventListener("message", (event) => {
          if (typeof handler !== "function") return;
          try {
            route(event.data, (messages) => handler.call(this, { data: { type: "message_batch", messages } }));
          } catch (error) {
            setTimeout(() => { throw error; });
          }
          handler.call(this, event);
        });
      }
    };
  }

  Object.defineProperty(stats, "playing", { get: () => playing !== null, enumerable: true });
  window.tableteachMotion = stats;
})();
