// The participant page: holds the one-tab lease, polls the server's state (GET /api/v1/me is the
// truth, so a reload or a lost connection resumes the same step), embeds the 3D view and renders
// each stage with participant-views.js. See docs/frontend.md.

import { ApiError, ParticipantApi, assetUrl, randomId, tokenFromLocation } from "./api.js";
import { h } from "./dom.js";
import * as views from "./participant-views.js";
import * as ops from "./participant-study-ops.js";

const TICK_MS = 1000;
const HEARTBEAT_MS = 5000;
const VIEWER_STALL_MS = 8000; // no 3D view connected for this long while one is shown: reload it
const REDIRECT_SECONDS = 8;

const api = new ParticipantApi(tokenFromLocation());
const tabId = randomId(12); // per page load: a reload frees the old lease on pagehide
const el = {
  screen: document.getElementById("screen"),
  task: document.getElementById("task"),
  panel: document.getElementById("panel"),
  viewer: document.getElementById("viewer"),
  frame: document.getElementById("viewer-frame"),
  note: document.getElementById("viewer-note"),
  banner: document.getElementById("banner"),
  top: document.getElementById("top-progress"),
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
  if (next) state = next;
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
  onFinish: () => act(() => api.finishDemonstration(guard())),
  onStartExecution: () => act(() => api.startExecution(guard())),
  onAssess: (acceptable) => act(() => api.assess(acceptable, guard())),
  onSubmit: (answers) => act(() => api.answerQuestionnaire(answers)),
  onQuiz: (answers) => act(() => api.act("/me/quiz", { answers })),
  onWithdraw: () => act(() => api.act("/me/withdraw", undefined)),
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

function render(force = false) {
  if (blocked) return;
  if (!state) return;
  const intro = state.stage === "task" && !introAcknowledged();
  const sig = JSON.stringify([state.stage, state.task, state.step, state.demonstration, state.execution,
    state.completion?.code, state.quiz, live.moving, live.caption, live.view, pending, intro]);
  if (sig === signature && !force) return;
  signature = sig;
  const key = JSON.stringify([state.stage, state.task?.index, state.step, state.execution?.status, intro]);
  const moved = key !== screenKey;
  screenKey = key;
  el.top.textContent = state.stage === "task" ? state.task.name : "";
  const withPending = { ...handlers, pending };
  switch (state.stage) {
    case "consent": showScreen(views.consentView(state, withPending)); break;
    case "instructions": showScreen(views.instructionsView(state, withPending)); break;
    case "questionnaire": showScreen(views.questionnaireView(state, withPending)); break;
    case "quiz": showScreen(ops.quizView(state, withPending)); break;
    case "withdrawn": case "screened_out":
      showScreen(ops.endedView(state, { redirectSeconds: REDIRECT_SECONDS })); scheduleRedirect(); break;
    case "done": showScreen(views.doneView(state, { redirectSeconds: REDIRECT_SECONDS })); scheduleRedirect(); break;
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
  const panel = views.taskPanel(state, live, { ...withPending, onStart: handlers.onStartExecution });
  // Keep the keyboard focus on the same button across a re-render (the panel is rebuilt).
  const focused = document.activeElement?.id || document.activeElement?.dataset?.object;
  el.panel.replaceChildren(panel);
  if (!moved && focused) {
    (document.getElementById(focused) || el.panel.querySelector(`[data-object="${focused}"]`))?.focus();
  }
  el.task.classList.toggle("no-view", viewer.available === false);
  syncViewer();
}

function closeViewer() {
  if (viewer.url) {
    el.frame.removeAttribute("src");
    viewer = { stepKey: null, taskIndex: null, url: null, available: null, noWatcherSince: null, busy: false };
  }
}

/** Ask the server to prepare the 3D view for this step; (re)load the frame when the task changes. */
async function syncViewer() {
  const stepKey = JSON.stringify([state.task.index, state.step?.kind, state.step?.index, state.execution?.status]);
  if (viewer.busy || stepKey === viewer.stepKey) return;
  viewer.busy = true;
  try {
    const view = await api.openView();
    viewer.stepKey = stepKey;
    viewer.available = view.available;
    if (!view.available) {
      el.note.textContent = "The 3D view is not available; use the buttons on the right.";
      el.task.classList.add("no-view");
      return;
    }
    el.task.classList.remove("no-view");
    if (viewer.taskIndex !== state.task.index || viewer.url !== view.url) {
      viewer.taskIndex = state.task.index;
      viewer.url = view.url;
      loadFrame();
    }
  } catch (error) {
    handleError(error);
  } finally {
    viewer.busy = false;
  }
}

function loadFrame() {
  viewer.noWatcherSince = Date.now();
  el.note.hidden = false;
  el.note.textContent = "Loading the 3D view…";
  el.frame.src = viewer.url;
}

el.frame.addEventListener("load", () => {
  if (!viewer.url) return;
  el.note.hidden = true;
  // Same origin: hide viser's pop-up notices (e.g. about software rendering); they cover the scene.
  try {
    const style = el.frame.contentDocument.createElement("style");
    style.textContent = ".mantine-Notifications-root { display: none !important; }";
    el.frame.contentDocument.head.append(style);
  } catch { /* not loaded from this origin: nothing to hide */ }
});

function watchViewer() {
  if (!viewer.url || state?.stage !== "task") return;
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

function scheduleRedirect() {
  const url = state.completion?.redirect_url;
  if (!url || redirectTimer) return;
  redirectTimer = setTimeout(() => window.location.assign(url), REDIRECT_SECONDS * 1000);
}

async function refresh() {
  const inTask = state?.stage === "task";
  const [next, robot] = await Promise.all([api.state(), inTask ? api.robot() : Promise.resolve(null)]);
  showBanner(el.banner.textContent.startsWith("The connection") ? "" : el.banner.textContent);
  setState(next, robot);
  watchViewer();
}

/** Hold the page's lease; false (and the "open elsewhere" screen) while another tab holds it. */
async function claim(takeover = false) {
  const answer = await api.claimTab(tabId, takeover);
  lastHeartbeat = Date.now();
  if (answer.held) {
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
    el.top.textContent = "";
    showScreen(views.elsewhereView(handlers));
    document.querySelector(".focus-target")?.focus();
  }
  return false;
}

async function tick() {
  try {
    if (blocked || Date.now() - lastHeartbeat > HEARTBEAT_MS) await claim();
    // Outside a task nothing changes on the server by itself, so only a task is polled.
    if (!blocked && (!state || state.stage === "task")) await refresh();
  } catch (error) {
    if (error instanceof ApiError) handleError(error);
    else console.error(error);
  }
  setTimeout(tick, TICK_MS);
}

window.addEventListener("pagehide", () => api.releaseTab(tabId));

async function start() {
  ops.installStyles(assetUrl);
  try {
    if (await claim()) await refresh();
  } catch (error) {
    if (error instanceof ApiError) handleError(error);
    else throw error;
  }
  setTimeout(tick, TICK_MS);
}

start();
