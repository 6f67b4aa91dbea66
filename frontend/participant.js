// The participant page: holds the one-tab lease, follows the server's state (GET /api/v1/me is the
// truth, so a reload or a lost connection resumes the same step) as soon as the server's change events
// say it changed, polling as a fallback, embeds the 3D view and renders each stage with
// participant-views.js. See docs/frontend.md.

import { ApiError, ParticipantApi, assetUrl, randomId, tokenFromLocation } from "./api.js";
import { h } from "./dom.js";
import * as views from "./participant-views.js";
import * as ops from "./participant-study-ops.js";
import { TopViewPlayer, motionFrames, restPoses, tablePicture } from "./participant-top-view.js";
import * as mode from "./participant-view-mode.js";

const TICK_MS = 1000; // polling while the change events are not connected
const TICK_WITH_EVENTS_MS = 5000; // with them: the lease heartbeat, and now and then a safety net
const SAFETY_NET_MS = 15000; // with change events, the state is read anyway at least this often during a task
const HEARTBEAT_MS = 5000;
const VIEWER_STALL_MS = 8000; // no 3D view connected for this long while one is shown: reload it
const REDIRECT_SECONDS = 8;
const PLAYBACK_POLL_MS = 250; // how often the page reads how far the 3D view has played the robot's attempt
const NO_PLAYER_GRACE_MS = 15000; // no player ever came for the robot's attempt: the answer is not held back longer
const PLAYER_RETRY_MS = 30000; // a player loading or gone quiet for this long is loaded again
const PLAYER_GIVE_UP_MS = 120000; // and after this long the answer goes ahead (the shown fraction says how much)
const IDLE_WARNING_SECONDS = 60; // "are you still there?" this long before the idle time-out
const MODE_NOTE_MS = 12000; // how long the page says why it shows the 2D view
const UNDER_WAY = ["consent", "instructions", "quiz", "task", "questionnaire"];
const FORMS = ["quiz", "questionnaire"];

const api = new ParticipantApi(tokenFromLocation());
const tabId = randomId(12); // per page load: a reload frees the old lease on pagehide
const el = {
  screen: document.getElementById("screen"),
  task: document.getElementById("task"),
  panel: document.getElementById("panel"),
  viewer: document.getElementById("viewer"),
  frame: document.getElementById("viewer-frame"),
  note: document.getElementById("viewer-note"),
  top: document.getElementById("top-view"),
  show3d: document.getElementById("view-3d"),
  show2d: document.getElementById("view-2d"),
  modeNote: document.getElementById("view-mode-note"),
  banner: document.getElementById("banner"),
  topProgress: document.getElementById("top-progress"),
  brand: document.querySelector(".topbar .brand"),
  progress: document.getElementById("study-progress"),
  progressBar: document.getElementById("study-progress-bar"),
  progressText: document.getElementById("study-progress-text"),
};

let state = null;
let live = { view: true, moving: false, caption: "", watchers: 0 };
let pending = false; // an action is on its way
let blocked = false; // another tab holds the page
let lastHeartbeat = 0;
let signature = "";
let screenKey = "";
let viewer = { stepKey: null, taskIndex: null, url: null, available: null, noWatcherSince: null, busy: false };
let redirectTimer = null;
let confirming = false; // the participant pressed finish with required objects missing: ask first
let events = null; // the EventSource of the server's change notices
let eventsOpen = false;
let refreshing = null; // the refresh under way; a change notice meanwhile asks for one more
let refreshAgain = false;
let refreshRobot = false; // the next read also asks for the robot's activity (a change notice brings it otherwise)
let lastRefreshed = 0;
// How much of the robot's attempt the 3D view has played (per step: task, kind, index): the answer waits for it.
let idleReadAt = Date.now(); // when state.idle was read
let shown = { step: null, playing: false, timed: false, fraction: null, complete: true, read: false, unreadSince: null,
  retried: false };
// 3D or 2D (participant-view-mode.js); the 2D view's picture and player, and what it shows now.
const probe = mode.probeWebgl();
let view = mode.initialMode(probe);
let noteTimer = null;
let top = { layout: null, picture: null, player: null, placed: null, motionKey: null, loading: false, retry: null,
  waiting: false };

function showBanner(text) {
  el.banner.textContent = text;
  el.banner.hidden = !text;
}

function introKey() {
  return `tableteach-intro-${state.participant_id}-${state.task.index}`;
}

function introAcknowledged() {
  try { return localStorage.getItem(introKey()) === "1"; } catch { return true; }
}

function guard() {
  return { task_index: state.task.index, step_kind: state.step.kind, step_index: state.step.index };
}

function setState(next, robot = null) {
  // An unchanged answer (304) is the same object: its idle seconds are as of when it was first read.
  if (next && next !== state) { state = next; idleReadAt = Date.now(); }
  if (robot) live = robot;
  render();
}

async function act(call) {
  pending = true;
  render();
  try {
    setState(await call());
    showBanner("");
  } catch (error) {
    handleError(error);
  } finally {
    pending = false;
    render();
  }
}

function handleError(error) {
  if (!(error instanceof ApiError)) throw error;
  if (error.status === 409 && error.state) {
    state = error.state;
    showBanner("The study had already moved on (perhaps in another tab). This page now shows where you are.");
  } else if (error.status === 0) {
    showBanner("The connection to the study server was lost. Trying again…");
  } else if (error.status === 401) {
    showBanner("This link is not valid any more. Please use the link you were given.");
  } else {
    showBanner(`Something went wrong: ${error.message}`);
  }
}

const handlers = {
  assetUrl,
  onAgree: () => act(() => api.consent(true, state.consent.version)),
  onDecline: () => act(() => api.consent(false, state.consent.version)),
  onStart: () => act(() => api.instructionsRead()),
  onBegin: () => {
    try { localStorage.setItem(introKey(), "1"); } catch { /* private mode: the intro shows again on reload */ }
    render(true);
  },
  onPlace: (obj) => act(() => api.place(obj, guard())),
  onFinish: () => {
    if (views.missingRequired(state).length) {
      confirming = true;
      render(true);
      document.getElementById("keep-going")?.focus();
      return;
    }
    act(() => api.finishDemonstration(guard()));
  },
  onConfirmFinish: () => { confirming = false; act(() => api.finishDemonstration(guard())); },
  onCancelFinish: () => { confirming = false; render(true); document.getElementById("finish")?.focus(); },
  onReplay: () => act(async () => {
    const next = await api.replay(guard());
    // The browser plays the recorded motion again: the answer buttons wait for it (the change event confirms it).
    live = { ...live, moving: true, caption: "Showing the robot's attempt again" };
    return next;
  }),
  onStartExecution: () => act(() => api.startExecution(guard())),
  onAssess: (acceptable) => act(() => api.assess(acceptable, guard(), shown.fraction)),
  onSubmit: (answers) => act(() => api.answerQuestionnaire(answers)),
  onQuiz: (answers) => act(() => api.act("/me/quiz", { answers })),
  onWithdraw: () => act(() => api.act("/me/withdraw", undefined)),
  onPaste: (field) => sendSignal("paste", field),
  onCopy: (code) => copyCode(code),
  onTakeOver: async () => {
    try {
      if (await claim(true)) await refresh();
    } catch (error) {
      handleError(error);
    }
  },
};

function showScreen(node) {
  el.task.hidden = true;
  el.screen.hidden = false;
  el.screen.replaceChildren(node);
  closeViewer();
}

function renderProgress() {
  const progress = state.progress;
  const show = Boolean(progress?.total) && state.stage !== "consent" && !finished();
  el.progress.hidden = !show;
  if (!show) return;
  el.progressBar.max = progress.total;
  el.progressBar.value = progress.done;
  el.progressText.textContent = views.studyProgressText(progress);
}

/** What of the progress changes the page: not seconds_left, which changes on every read. */
function progressKey() {
  const p = state.progress;
  return p ? [p.done, p.total, p.minutes_left] : null;
}

/** Ask before the tab is closed or left with Back while the study is under way. */
function warnBeforeLeaving(event) {
  if (!state || !["instructions", "quiz", "task", "questionnaire"].includes(state.stage)) return;
  event.preventDefault();
  event.returnValue = "";
}

function render(force = false) {
  if (blocked) return;
  if (!state) return;
  const intro = state.stage === "task" && !introAcknowledged();
  const sig = JSON.stringify([state.stage, state.task, state.step, state.demonstration, state.execution,
    state.completion?.code, state.quiz, progressKey(), live.moving, live.caption, live.view, pending, intro,
    confirming, view.mode, shown.complete, shown.fraction === null ? null : Math.round(shown.fraction * 20)]);
  if (sig === signature && !force) return;
  signature = sig;
  const key = JSON.stringify([state.stage, state.task?.index, state.step, state.execution?.status, intro,
    state.quiz?.failed_attempts]);
  const moved = key !== screenKey;
  screenKey = key;
  // A form the participant is filling in is never rebuilt under them (their answers would go): only its bar.
  if (!moved && !force && FORMS.includes(state.stage) && el.screen.firstChild) {
    renderProgress();
    for (const button of el.screen.querySelectorAll("button[type=submit]")) button.disabled = pending;
    return;
  }
  if (moved) confirming = false;
  el.topProgress.textContent = state.stage === "task" ? state.task.name : "";
  if (state.own_objects) el.brand.textContent = document.title = "Teach a robot a task"; // not a dinner table
  renderProgress();
  document.body.classList.toggle("in-task", state.stage === "task" && !intro);
  const withPending = { ...handlers, pending, confirming };
  switch (state.stage) {
    case "consent": showScreen(views.consentView(state, withPending)); break;
    case "instructions": showScreen(views.instructionsView(state, withPending)); break;
    case "questionnaire": showScreen(views.questionnaireView(state, withPending)); break;
    case "quiz": showScreen(ops.quizView(state, withPending)); break;
    case "withdrawn": case "screened_out": leaveScreen((secondsLeft) => ops.endedView(state, { secondsLeft, onCopy: handlers.onCopy })); break;
    case "done": leaveScreen((secondsLeft) => views.doneView(state, { secondsLeft, onCopy: handlers.onCopy })); break;
    case "task":
      if (intro) { showScreen(views.taskIntroView(state, withPending)); break; }
      renderTask(withPending, moved);
      break;
    default: showScreen(h("p", {}, `Unknown stage ${state.stage}.`));
  }
  ops.syncWithdrawLink(state, withPending);
  if (moved) {
    window.scrollTo(0, 0);
    document.querySelector(".focus-target")?.focus({ preventScroll: true });
  }
}

function renderTask(withPending, moved) {
  el.screen.hidden = true;
  el.task.hidden = false;
  const panel = views.taskPanel(state, { ...live, shown, mode: view.mode }, { ...withPending, onStart: handlers.onStartExecution });
  // Keep the keyboard focus on the same button across a re-render (the panel is rebuilt).
  const focused = document.activeElement?.id || document.activeElement?.dataset?.object;
  el.panel.replaceChildren(panel);
  if (!moved && focused) {
    (document.getElementById(focused) || el.panel.querySelector(`[data-object="${focused}"]`))?.focus();
  }
  el.task.classList.toggle("no-view", viewer.available === false);
  syncViewer().then(syncTopView);
}

function closeViewer() {
  top.player?.stop();
  top.placed = null;
  top.motionKey = null;
  if (viewer.url) {
    el.frame.removeAttribute("src");
    viewer = { stepKey: null, taskIndex: null, url: null, available: null, noWatcherSince: null, busy: false };
  }
}

/** Ask the server to prepare the 3D view for this step; (re)load the frame when the task changes. */
async function syncViewer() {
  // "Watch it again" counts in the key: the server then gives the player a new address, which plays it again.
  const stepKey = JSON.stringify([state.task.index, state.step?.kind, state.step?.index, state.execution?.status,
    state.execution?.replays]);
  if (viewer.busy || stepKey === viewer.stepKey) return;
  viewer.busy = true;
  try {
    const answer = await api.openView();
    viewer.stepKey = stepKey;
    viewer.available = answer.available;
    if (!answer.available) {
      el.note.textContent = "The 3D view is not available; use the buttons on the right.";
      el.task.classList.add("no-view");
      return;
    }
    el.task.classList.remove("no-view");
    if (viewer.taskIndex !== state.task.index || viewer.url !== answer.url) {
      viewer.taskIndex = state.task.index;
      viewer.url = answer.url;
      if (view.mode === "3d") loadFrame();
    }
  } catch (error) {
    handleError(error);
  } finally {
    viewer.busy = false;
  }
}

function loadFrame() {
  if (view.mode !== "3d") return;
  viewer.noWatcherSince = Date.now();
  viewer.frameLoaded = false;
  el.note.hidden = false;
  el.note.textContent = "Loading the 3D view…";
  el.frame.src = mode.viewerUrl(viewer.url, probe);
}

// The viewer page the server sends already hides viser's control panel and pop-up notices.
el.frame.addEventListener("load", () => {
  viewer.frameLoaded = true;
  if (viewer.url) el.note.hidden = true;
});

/** Show the 3D or the 2D view (the other stops: the 3D view's frame is emptied, the 2D player stopped). */
function applyMode(why = null) {
  const flat = view.mode === "2d";
  el.task.classList.toggle("flat", flat);
  el.top.hidden = !flat;
  el.frame.hidden = flat;
  el.show3d.setAttribute("aria-pressed", String(!flat));
  el.show2d.setAttribute("aria-pressed", String(flat));
  el.show3d.disabled = !probe.webgl;
  el.modeNote.textContent = why ?? "";
  el.modeNote.hidden = !why;
  clearTimeout(noteTimer);
  if (why) noteTimer = setTimeout(() => { el.modeNote.hidden = true; }, MODE_NOTE_MS); // it covers the tables
  if (flat) {
    el.frame.removeAttribute("src");
    el.note.hidden = true;
    viewer.noWatcherSince = null;
  } else {
    top.player?.stop();
    top.placed = null;
    top.motionKey = null;
    if (viewer.url) loadFrame();
  }
}

function switchMode(next, why = null) {
  if (next === view.mode) return;
  view = { mode: next, reason: why ? "slow" : "choice" };
  applyMode(why);
  render(true);
}

/** Bring the 2D view up to date with the state: a still table, the last placement glided, or the step's recording. */
async function syncTopView() {
  if (view.mode !== "2d" || state?.stage !== "task" || viewer.available === false || top.loading) return;
  const ex = state.execution;
  const robotTurn = ex && ex.status !== "not_started" && ["query", "test"].includes(state.step?.kind);
  const motionKey = robotTurn ? JSON.stringify([state.task.index, ex.kind, ex.index, ex.replays ?? 0]) : null;
  if (motionKey && !(Number(ex.motion_seconds) > 0)) {
    // The robot is getting ready: its motion plays once its clock has started (as the 3D view's does).
    if (top.layout && top.placed !== null) { top.player.still(restPoses(top.layout, [])); top.placed = null; }
    if (top.layout) return;
  }
  if (!top.layout || (motionKey && motionKey !== top.motionKey)) {
    top.loading = true;
    let answer;
    try {
      answer = await api.topView();
    } catch (error) {
      if (error instanceof ApiError) handleError(error); else console.error(error);
      return;
    } finally {
      top.loading = false;
    }
    if (!top.layout) {
      top.layout = answer.layout;
      top.picture = tablePicture(answer.layout, { onPick: (obj) => pickInTopView(obj) });
      top.player = new TopViewPlayer(top.picture);
      el.top.replaceChildren(top.picture.element);
    }
    if (motionKey) {
      if (!answer.motion || !(Number(state.execution?.motion_seconds) > 0)) {
        // The robot is still working its motion out: ask again shortly.
        clearTimeout(top.retry);
        top.waiting = true;
        if (!answer.motion) top.retry = setTimeout(() => syncTopView(), 700);
        top.player.still(restPoses(top.layout, []));
        top.placed = null;
        return;
      }
      top.motionKey = motionKey;
      top.placed = null;
      top.waiting = false;
      // Switched to 2D part-way through the attempt: go on from where the 3D view had got to.
      const from = shown.step === JSON.stringify([state.task.index, ex.kind, ex.index]) && !shown.complete
        ? shown.fraction ?? 0 : 0;
      top.player.play(motionFrames(answer.motion, top.layout), Number(state.execution.motion_seconds) || 0, { from });
      top.picture.describe(`The tables from above: the robot places ${ex.events.map((o) => `the ${o.replaceAll("_", " ")}`).join(", ")}`);
      return;
    }
  }
  if (motionKey) return; // the recording is playing or has played
  top.motionKey = null;
  top.waiting = false;
  const placed = ["practice", "demonstration"].includes(state.step?.kind) ? state.demonstration?.placed ?? [] : [];
  const previous = top.placed;
  top.placed = [...placed];
  const to = restPoses(top.layout, placed);
  top.picture.describe(placed.length
    ? `The tables from above: on Table B, ${placed.map((o) => `the ${o.replaceAll("_", " ")}`).join(", ")}`
    : "The tables from above: every object is on Table A");
  const added = previous && placed.length === previous.length + 1 && previous.every((o, i) => placed[i] === o);
  if (added) top.player.place(placed.at(-1), restPoses(top.layout, previous), to);
  else if (JSON.stringify(previous) !== JSON.stringify(placed)) top.player.still(to);
}

/** A click on an object in the 2D view places it, as a click in the 3D view does (during a demonstration). */
function pickInTopView(obj) {
  if (!state || state.stage !== "task" || pending || live.moving) return;
  if (!["practice", "demonstration"].includes(state.step?.kind)) return;
  if (state.demonstration?.placed?.includes(obj) || state.demonstration?.settled === false) return;
  handlers.onPlace(obj);
}

function watchViewer() {
  if (!viewer.url || state?.stage !== "task" || view.mode !== "3d") return;
  // A recorded execution plays from a file in the browser: no live connection to watch over.
  if (viewer.url.includes("playbackPath=")) return;
  if (live.watchers > 0) {
    viewer.noWatcherSince = null;
  } else if (viewer.noWatcherSince === null) {
    viewer.noWatcherSince = Date.now();
  } else if (Date.now() - viewer.noWatcherSince > VIEWER_STALL_MS) {
    loadFrame(); // the view's connection was lost (server restart, network): connect again
  }
}

/** Send one attention signal while the study is under way; a lost one is not worth a retry or a banner. */
function sendSignal(kind, field = null) {
  if (!state || !UNDER_WAY.includes(state.stage) || blocked) return;
  api.signal(kind, field).catch(() => {});
}

/** Copy the completion code; without the Clipboard API (an insecure page), select it so the participant can copy. */
async function copyCode(code) {
  const note = document.getElementById("copy-note");
  try {
    await navigator.clipboard.writeText(code);
    if (note) note.textContent = "Copied.";
  } catch {
    const node = document.getElementById("completion-code");
    if (node) window.getSelection()?.selectAllChildren(node);
    if (note) note.textContent = "Selected: press Ctrl+C (or Cmd+C) to copy it.";
  }
}

/** "Are you still there?" a minute before the study's idle time-out (state.idle: its length and the idle time). */
function watchIdle() {
  const idle = state && UNDER_WAY.includes(state.stage) && !blocked ? state.idle : null;
  const dialog = document.getElementById("idle-dialog");
  if (!idle) { dialog?.close(); return; }
  const left = idle.timeout_seconds - idle.idle_seconds - (Date.now() - idleReadAt) / 1000;
  if (left > IDLE_WARNING_SECONDS) { if (dialog?.open) dialog.close(); return; }
  const box = dialog ?? ops.idleDialog(async () => {
    box.close();
    try { await api.signal("still_here"); await refreshState(); } catch (error) { handleError(error); }
  });
  const seconds = Math.max(0, Math.ceil(left));
  box.querySelector("#idle-seconds").textContent = `${seconds} second${seconds === 1 ? "" : "s"}`;
  if (!box.open) { box.showModal ? box.showModal() : box.setAttribute("open", ""); }
  if (left <= 0) refreshState().catch(() => {}); // the server then says the session has ended
}

async function refreshState() {
  setState(await api.state());
}

/** How far the view has played the recorded attempt: {seconds} when a player can be read, else {loading: true}
 * while one is on its way (the 3D player downloading its file, the 2D view fetching or waiting for the recording),
 * else {} (no player: the view failed). */
function playerReading() {
  if (view.mode === "2d") {
    if (top.player?.frames) return { seconds: top.player.position };
    return top.loading || top.waiting ? { loading: true } : {};
  }
  try {
    const doc = el.frame.contentDocument;
    const thumb = doc?.querySelector('.mantine-Slider-root [role="slider"]');
    const seconds = thumb ? Number(thumb.getAttribute("aria-valuenow")) : NaN;
    if (Number.isFinite(seconds)) return { seconds };
    // viser shows a progress bar while it downloads the recording; before that the frame is still loading
    const loading = !viewer.frameLoaded || Boolean(doc?.querySelector(".mantine-Progress-root"));
    return loading ? { loading: true } : {};
  } catch {
    return { loading: true }; // the frame is between pages
  }
}

/** A fresh record of how much of this step's attempt was shown. */
function shownRecord(step, playing, motion) {
  return { step, playing, timed: motion > 0, fraction: playing && motion > 0 ? 0 : null,
    complete: !playing || motion <= 0, read: false, unreadSince: null, retried: false };
}

/** Follow how much of the robot's attempt has been shown; the answer buttons unlock once it has played to the end.
 *
 * A player that was never there (the view failed) unlocks them after NO_PLAYER_GRACE_MS. One that is loading, or
 * that was read and then went quiet (the frame reloading, a page stalled by software WebGL, the switch to 2D), holds
 * them: it is reloaded after PLAYER_RETRY_MS and only after PLAYER_GIVE_UP_MS does the answer go ahead, the fraction
 * sent with it saying how much was seen. */
function watchPlayback() {
  const ex = state?.stage === "task" ? state.execution : null;
  if (!ex || ex.status === "not_started") return;
  const step = JSON.stringify([state.task.index, ex.kind, ex.index]);
  const motion = Number(ex.motion_seconds) || 0;
  // The 2D player plays the recording over the stored motion length; the 3D one plays it from a file.
  const playing = view.mode === "2d" || (Boolean(viewer.url?.includes("playbackPath=")) && viewer.available !== false);
  // A record started before there was anything to play (the live view, or the 2D view before the plan arrived)
  // starts again once there is: otherwise the answer would unlock before the attempt had been shown.
  if (shown.step !== step || (playing && !shown.playing) || (motion > 0 && !shown.timed)) {
    shown = shownRecord(step, playing, motion);
  }
  if (shown.complete && shown.fraction === 1) return;
  const before = JSON.stringify(shown);
  const reading = playing ? playerReading() : {};
  if (reading.seconds !== undefined && motion > 0) {
    shown.unreadSince = null;
    shown.read = true;
    const fraction = view.mode === "2d" ? top.player.fraction : reading.seconds / motion;
    shown.fraction = Math.max(shown.fraction ?? 0, Math.min(1, fraction ?? 0));
    if (shown.fraction >= 0.995) { shown.fraction = 1; shown.complete = true; }
  } else if (ex.status === "finished" && !shown.complete) {
    shown.unreadSince ??= Date.now();
    const quiet = Date.now() - shown.unreadSince;
    if (!shown.read && !reading.loading) {
      if (quiet > NO_PLAYER_GRACE_MS) shown.complete = true;
    } else if (quiet > PLAYER_GIVE_UP_MS) {
      shown.complete = true;
    } else if (quiet > PLAYER_RETRY_MS && !shown.retried) {
      shown.retried = true;
      reloadPlayer();
    }
  }
  if (JSON.stringify(shown) === before) return;
  el.viewer.dataset.shownFraction = shown.fraction === null ? "" : shown.fraction.toFixed(3); // for tests and support
  render();
}

/** Load the current player again (the 3D view's frame, or the 2D view's recording). */
function reloadPlayer() {
  if (view.mode === "3d") { loadFrame(); return; }
  top.motionKey = null;
  syncTopView();
}

/** The last screen (finished, or left early): `view(secondsLeft)` builds it; with a redirect address it counts
 * down once per second, then goes there. */
function leaveScreen(view) {
  const url = state.completion?.redirect_url;
  let left = REDIRECT_SECONDS;
  events?.close();
  showScreen(view(url ? left : null));
  if (!url || redirectTimer) return;
  redirectTimer = setInterval(() => {
    left -= 1;
    const counter = document.getElementById("countdown");
    if (counter) counter.textContent = `You will be taken back in ${left} second${left === 1 ? "" : "s"}. `;
    if (left <= 0) {
      clearInterval(redirectTimer);
      window.location.assign(url);
    }
  }, 1000);
}

/** Read the state (and, during a task, the robot's activity unless a change notice just brought it). */
async function refresh({ withRobot = true } = {}) {
  refreshRobot ||= withRobot;
  if (refreshing) {
    refreshAgain = true; // a change arrived while reading: read once more afterwards
    return refreshing;
  }
  refreshing = (async () => {
    do {
      refreshAgain = false;
      const inTask = state?.stage === "task";
      const readRobot = inTask && refreshRobot;
      refreshRobot = false;
      const [next, robot] = await Promise.all([api.state(), readRobot ? api.robot() : Promise.resolve(null)]);
      showBanner(el.banner.textContent.startsWith("The connection") ? "" : el.banner.textContent);
      // The robot's activity is only read during a task; entering one reads it at once.
      const enteredTask = !inTask && next.stage === "task";
      setState(next, robot);
      if (enteredTask) { refreshAgain = true; refreshRobot = true; }
      watchViewer();
    } while (refreshAgain);
    lastRefreshed = Date.now();
  })();
  try {
    await refreshing;
  } finally {
    refreshing = null;
  }
}

/** Follow the server's change notices (server-sent events on this page's own address); polling stays as a fallback. */
function listen() {
  if (events || typeof EventSource === "undefined") return;
  events = new EventSource(`${window.location.pathname.replace(/\/$/, "")}/events`);
  events.addEventListener("open", () => { eventsOpen = true; });
  events.addEventListener("error", () => { eventsOpen = false; }); // EventSource reconnects by itself
  // A newer stream of this participant (another tab or a reload) took this one's place: poll from now on.
  events.addEventListener("superseded", () => { events.close(); eventsOpen = false; });
  events.addEventListener("change", (event) => {
    if (blocked) return;
    // The event carries the robot's activity (shown at once) and the state's tag: the state is read only when
    // that tag is not the one this page holds.
    let data = null;
    try { data = JSON.parse(event.data); } catch { /* an older server: read everything */ }
    const robot = data?.robot ?? null;
    if (robot && state?.stage === "task") setState(null, robot);
    if (data?.state && (data.state === api.heldTag("/me") || data.state === state?.etag)) return;
    refresh({ withRobot: !robot }).catch((error) => {
      if (error instanceof ApiError) handleError(error); else console.error(error);
    });
  });
}

function finished() {
  return Boolean(state) && ["done", "withdrawn", "screened_out"].includes(state.stage);
}

/** Hold the page's lease; false (and the "open elsewhere" screen) while another tab holds it. */
async function claim(takeover = false) {
  const answer = await api.claimTab(tabId, takeover);
  lastHeartbeat = Date.now();
  if (answer.held) {
    listen();
    if (blocked) {
      blocked = false;
      signature = "";
      screenKey = "";
    }
    return true;
  }
  if (!blocked) {
    blocked = true;
    state = null;
    el.topProgress.textContent = "";
    el.progress.hidden = true;
    ops.syncWithdrawLink(null, handlers); // the tab that holds the page offers withdrawal
    showScreen(views.elsewhereView(handlers));
    document.querySelector(".focus-target")?.focus();
  }
  return false;
}

async function tick() {
  if (finished()) return; // nothing changes any more: no lease, no polling
  try {
    if (blocked || Date.now() - lastHeartbeat > HEARTBEAT_MS) await claim();
    // Outside a task nothing changes on the server by itself, so only a task is polled; with change events
    // arriving, only as a safety net.
    const due = !eventsOpen || Date.now() - lastRefreshed >= SAFETY_NET_MS;
    if (!blocked && (!state || state.stage === "task") && due) await refresh();
  } catch (error) {
    if (error instanceof ApiError) handleError(error);
    else console.error(error);
  }
  setTimeout(tick, eventsOpen ? TICK_WITH_EVENTS_MS : TICK_MS);
}

setInterval(watchPlayback, PLAYBACK_POLL_MS);
el.show3d.addEventListener("click", () => { mode.storeChoice("3d"); switchMode("3d"); });
el.show2d.addEventListener("click", () => { mode.storeChoice("2d"); switchMode("2d"); });
mode.watchStalls(() => view.mode === "3d" && view.reason !== "choice" && Boolean(el.frame.getAttribute("src")),
  () => switchMode("2d", "The 3D view was too slow on this device, so the tables are shown in 2D. "
    + "The 3D button switches back."));
setInterval(watchIdle, 1000);
document.addEventListener("visibilitychange", () => { if (document.visibilityState === "hidden") sendSignal("tab_hidden"); });
// Focus moving into the 3D view's frame blurs the window too: only a window left while the tab stays visible counts.
window.addEventListener("blur", () => setTimeout(() => {
  if (!document.hasFocus() && document.visibilityState === "visible") sendSignal("window_blur");
}, 0));
window.addEventListener("pagehide", () => { if (!finished()) api.releaseTab(tabId); });
window.addEventListener("beforeunload", warnBeforeLeaving);

async function start() {
  ops.installStyles(assetUrl);
  applyMode(view.reason === "no-webgl" ? "This browser cannot show 3D, so the tables are shown in 2D." : null);
  try {
    // A finished participant who opens the link again sees their completion code, in any tab.
    state = await api.state();
    if (finished()) {
      render(true);
      return;
    }
    if (await claim()) await refresh();
  } catch (error) {
    if (error instanceof ApiError) handleError(error);
    else throw error;
  }
  setTimeout(tick, TICK_MS);
}

start();
