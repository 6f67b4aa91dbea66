// What the participant sees at each stage: functions from (state, handlers) to DOM nodes. No fetching
// here; participant.js owns the state and passes callbacks. Plain words only: no formulas, no jargon.

import { h, pretty } from "./dom.js";

const list = (objs) => (objs.length ? objs.map(pretty).join(", ") : "nothing yet");
/** "the bowl", "the bowl and the knife", "the bowl, the knife and the fork". */
const theList = (objs) => {
  const named = objs.map((o) => `the ${pretty(o)}`);
  return named.length > 1 ? `${named.slice(0, -1).join(", ")} and ${named[named.length - 1]}` : named.join("");
};
const GOAL_PICTURES = { task1: "goal-task1.png", task2: "goal-task2.png" };
const NUMBERS = ["no", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten"];
/** "a lunch box, an apple and a mug": a study's own objects as the instructions name them. */
const someList = (objs) => {
  const named = objs.map((o) => `${/^[aeiou]/.test(o) ? "an" : "a"} ${pretty(o)}`);
  return named.length > 1 ? `${named.slice(0, -1).join(", ")} and ${named[named.length - 1]}` : named.join("");
};
/** What the robot does, in the page's words: the dinner table's, or a study's own objects' (any task). */
const doing = (state) => (state?.own_objects ? "do the task" : "set the table");
const STEP_NAMES = { practice: "Practice round", demonstration: "Demonstration", query: "Question", test: "Test" };
const LIKERT = ["Strongly disagree", "Disagree", "Neither", "Agree", "Strongly agree"];

function heading(text) {
  return h("h1", { tabindex: "-1", class: "focus-target" }, text);
}

/** The study's information sheet: its text, then the structured sections (who, contact, ethics approval,
 * duration, payment, what is recorded, retention, withdrawal) and the version agreed to. */
export function consentSheet(state) {
  const consent = state.consent;
  const sections = [...(consent.sections || [])];
  if (!sections.some((s) => s.key === "duration") && state.progress?.minutes_left) {
    const at = sections.findIndex((s) => ["payment", "recorded", "retention", "withdrawal"].includes(s.key));
    const duration = { key: "duration", heading: "How long it takes", text: `About ${state.progress.minutes_left} minutes.` };
    sections.splice(at < 0 ? sections.length : at, 0, duration);
  }
  return h("div", { class: "consent-sheet", id: "consent-sheet" },
    h("p", { class: "consent-text" }, consent.text),
    sections.map((s) => h("section", { class: "consent-section", "data-section": s.key },
      h("h2", {}, s.heading), h("p", {}, s.text))),
    h("p", { class: "consent-version" }, `Information sheet version ${consent.version}`,
      consent.given_at ? ` · you agreed on ${new Date(consent.given_at).toLocaleString()}` : ""));
}

function printButton() {
  return h("button", { type: "button", id: "print-consent", onclick: () => window.print() }, "Print or save a copy");
}

export function consentView(state, { onAgree, onDecline }) {
  return h("section", { class: "card narrow consent" },
    heading("About this study"),
    state.consent.anonymous && state.consent.allow_anonymous
      ? h("p", { class: "notice", id: "anonymous-note" }, "You are taking part without a Prolific ID: nothing links "
        + "your answers to an account, and no payment can be made through Prolific for this session.") : null,
    consentSheet(state),
    h("div", { class: "buttons no-print" }, printButton()),
    h("p", { class: "question no-print" }, "Do you agree to take part?"),
    h("div", { class: "buttons no-print" },
      h("button", { class: "primary", onclick: onAgree }, "I agree, continue"),
      h("button", { onclick: onDecline }, "I do not agree")));
}

/** What the study asks of the participant (shown before the first task, and again from the quiz); `state` names a
 * study's own objects (without it, or for the dinner table, the paper's words). */
export function instructionsBody(state = null) {
  const own = state?.own_objects;
  const intro = own
    ? h("p", {}, `You will teach a robot arm a task with ${NUMBERS[own.length] ?? own.length} objects (`,
      someList(own.map((o) => o.name)), "). The arm takes them from Table A, on the right of the 3D view, and puts ",
      "them on Table B, on the left.")
    : h("p", {}, "You will teach a robot arm to set a dinner table. The arm takes five objects (a dinner plate, a small ",
      "plate, a bowl, a knife and a fork) from Table A, on the right of the 3D view, and puts them on Table B, on ",
      "the left.");
  return h("div", { class: "instructions-body" },
    intro,
    h("ol", {},
      h("li", {}, h("strong", {}, "You show it. "), "Click an object in the 3D view and the robot places it. ",
        "Click the objects in the order you want. Press the finish button when you are done; you do not have to ",
        "place every object if the task says so."),
      h("li", {}, h("strong", {}, "It asks you. "), "The robot tries the task its own way. When it has finished, ",
        "tell it whether what it did is acceptable for the task."),
      h("li", {}, h("strong", {}, "It shows you. "), `At the end of each task the robot ${own ? "does the task" : "sets the table"} by itself `,
        "a few times so you can see what it has learned.")),
    h("p", {}, "The order in which things are placed can matter. Before each task you will see what the table should ",
      "look like at the end."));
}

export function instructionsView(state, { onStart }) {
  return h("section", { class: "card narrow" },
    heading("How this works"),
    instructionsBody(state),
    h("div", { class: "buttons" }, h("button", { class: "primary", onclick: onStart }, "Start")));
}

export function goalFigure(task, assetUrl) {
  // A study with its own objects: the server draws each task's goal from its layout (task.goal_picture).
  const picture = task.goal_picture || (GOAL_PICTURES[task.key] && assetUrl(GOAL_PICTURES[task.key]));
  if (!picture) return null;
  return h("figure", { class: "goal" },
    h("img", { src: picture, alt: `Table B when ${task.name} is done: the objects in their places, labelled` }),
    h("figcaption", {}, "What Table B should look like at the end."));
}

export function taskIntroView(state, { onBegin, assetUrl }) {
  const task = state.task;
  // The goal picture comes before the button on every screen: on a phone the two stack in this order.
  return h("section", { class: "card intro" },
    h("p", { class: "eyebrow" }, `Task ${(task.position ?? task.index) + 1} of ${task.total}`),
    heading(task.name),
    h("div", { class: "intro-body" },
      h("p", { class: "instructions" }, task.instructions),
      goalFigure(task, assetUrl),
      h("div", { class: "buttons intro-start" }, h("button", { class: "primary", onclick: onBegin }, "Begin this task"))));
}

/** The study-wide progress line: "Step 5 of 14 · about 12 minutes left". */
export function studyProgressText(progress) {
  if (!progress || !progress.total) return "";
  const left = progress.minutes_left === 1 ? "about 1 minute left" : `about ${progress.minutes_left} minutes left`;
  return `Step ${Math.min(progress.done + 1, progress.total)} of ${progress.total} · ${left}`;
}

/** Objects the task requires that are not on the table yet (the finish button asks before ending without them). */
export function missingRequired(state) {
  const placed = state.demonstration?.placed || [];
  return (state.task?.required || []).filter((o) => !placed.includes(o));
}

export function progressText(state) {
  const { task, step } = state;
  if (!task || !step) return "";
  return `Task ${(task.position ?? task.index) + 1} of ${task.total} · ${STEP_NAMES[step.kind]} ${step.index + 1} of ${step.total}`;
}

/** The side panel next to the 3D view during a task. `live` is the robot's activity ({moving, caption}). */
export function taskPanel(state, live, handlers) {
  const { step } = state;
  const body = step.kind === "practice" || step.kind === "demonstration"
    ? demonstrationPanel(state, live, handlers)
    : executionPanel(state, live, handlers);
  return h("div", { class: "panel-inner" },
    h("p", { class: "eyebrow", id: "progress" }, progressText(state)),
    body,
    h("details", { class: "reminder" },
      h("summary", {}, "Show the task again"),
      h("p", {}, state.task.instructions),
      goalFigure(state.task, handlers.assetUrl)));
}

function statusLine(text, busy = false) {
  return h("p", { class: busy ? "status busy" : "status", id: "status", role: "status", "aria-live": "polite" }, text);
}

function demonstrationPanel(state, live, { onPlace, onFinish, onConfirmFinish, onCancelFinish, confirming, pending }) {
  const { step, demonstration } = state;
  const placed = demonstration.placed;
  const waiting = state.objects.filter((o) => !placed.includes(o));
  const placing = demonstration.settled === false; // stored, but the robot has not reported the table yet
  const moving = live.moving || pending || placing;
  const practice = step.kind === "practice";
  const missing = missingRequired(state);
  const caption = live.caption || (placing ? `The robot is placing the ${pretty(placed[placed.length - 1])}` : "");
  const status = moving
    ? (caption ? `${caption}. Please wait until it has finished.` : "The robot is busy. Please wait.")
    : waiting.length
      ? `Click the next object ${live.view === false ? "below" : live.mode === "2d" ? "in the 2D view" : "in the 3D view"}, or finish ${state.own_objects ? "when the task is done" : "if the table is set"}.`
      : "All objects are on Table B. Press the finish button.";
  const finishLabel = practice ? "Finish practice" : "Finish demonstration";
  return h("div", {},
    heading(practice ? "Practice: try it out" : `Show the robot how to ${doing(state)}`),
    h("p", { class: "explain" }, practice
      ? "This round does not count. Click objects on Table A (right) and watch the robot put them on Table B (left)."
      : "Click the objects on Table A (right) in the order you want them on Table B (left). The robot places each one."),
    statusLine(status, moving),
    h("p", { class: "placed" }, h("strong", {}, "On Table B: "), list(placed)),
    waiting.length ? h("div", { class: "object-buttons" },
      h("p", { class: "hint" }, "Or choose from this list:"),
      waiting.map((obj) => h("button", { class: "object", "data-object": obj, disabled: moving,
        onclick: () => onPlace(obj) }, pretty(obj)))) : null,
    confirming && !moving
      ? h("div", { class: "confirm", id: "confirm-finish", role: "alertdialog", "aria-labelledby": "confirm-text" },
        h("p", { id: "confirm-text" }, h("strong", {}, `This task asks for ${theList(missing)} too`),
          `, and ${missing.length === 1 ? "it is" : "they are"} not on Table B yet. Finish anyway?`),
        h("div", { class: "buttons" },
          h("button", { id: "keep-going", class: "primary", onclick: onCancelFinish }, "No, keep placing"),
          h("button", { id: "finish-anyway", onclick: onConfirmFinish }, "Yes, finish now")))
      : h("div", { class: "buttons" },
        h("button", { class: "primary", id: "finish", disabled: moving, onclick: onFinish }, finishLabel)));
}

function executionPanel(state, live, { onStart, onAssess, onReplay, pending }) {
  const { step, execution } = state;
  const query = step.kind === "query";
  const title = query ? "The robot has a question" : "The robot shows what it learned";
  if (execution.status === "not_started") {
    return h("div", {},
      heading(title),
      h("p", {}, query
        ? `The robot will ${doing(state)} its own way. Watch it, then tell it whether that way is acceptable for this task.`
        : `The robot will ${doing(state)} by itself. Watch it, then say whether it did the task correctly.`),
      statusLine("Press the button when you are ready to watch."),
      h("div", { class: "buttons" },
        h("button", { class: "primary", id: "start", disabled: pending, onclick: onStart }, "Watch the robot")));
  }
  const events = execution.events || [];
  if (execution.status === "running") {
    return h("div", {},
      heading(title),
      statusLine(live.caption ? `${live.caption}.` : `The robot is ${state.own_objects ? "placing objects" : "setting the table"} (${events.length} objects).`, true),
      h("p", { class: "hint" }, "The buttons to answer appear when the robot has finished."));
  }
  const finalLabels = execution.trace?.length ? execution.trace[execution.trace.length - 1] : [];
  const missed = events.filter((o) => !finalLabels.includes(o));
  const notPlaced = state.objects.filter((o) => !events.includes(o));
  const replaying = live.moving;
  // The answer waits until the page has played the robot's attempt to its end (or the page cannot tell).
  const shown = live.shown ?? { fraction: null, complete: true };
  const unseen = !shown.complete;
  const locked = pending || replaying || unseen;
  const percent = shown.fraction === null ? null : Math.round(100 * shown.fraction);
  const status = replaying
    ? statusLine(live.caption ? `${live.caption}. The buttons work again when it has finished.` : "The robot is busy.", true)
    : unseen
      ? statusLine(`The robot has finished; the ${live.mode === "2d" ? "2D" : "3D"} view is still showing it (${percent ?? 0}% shown). `
        + "The buttons work when it has been shown to the end.", true)
      : statusLine("The robot has finished.");
  return h("div", {},
    heading(title),
    status,
    h("div", { class: "outcome", id: "outcome" },
      h("p", { class: "placed" }, h("strong", {}, "It placed, in this order: "),
        events.length ? events.map((o, i) => `${i + 1}. the ${pretty(o)}`).join(", ") : "nothing"),
      h("p", { class: "placed not-placed" }, h("strong", {}, "It did not place: "),
        notPlaced.length ? theList(notPlaced) : `nothing (it placed all ${NUMBERS[state.objects.length] ?? state.objects.length} objects)`),
      missed.length ? h("p", { class: "placed" }, h("strong", {}, "Not in place at the end: "), theList(missed)) : null),
    h("p", { class: "question" }, query
      ? (state.own_objects ? "Is this an acceptable way to do this task?" : "Is this an acceptable way to set the table for this task?")
      : "Did the robot do the task correctly?"),
    h("div", { class: "buttons" },
      h("button", { class: "primary good", id: "acceptable", disabled: locked,
        onclick: () => onAssess(true) }, query ? "Acceptable" : "Yes, correct"),
      h("button", { class: "primary bad", id: "unacceptable", disabled: locked,
        onclick: () => onAssess(false) }, query ? "Unacceptable" : "No, not correct")),
    live.view ? h("div", { class: "buttons" },
      h("button", { id: "watch-again", disabled: pending || replaying, onclick: onReplay }, "Watch it again")) : null);
}

// Standard questionnaires' scales (services/instruments.py): [lowest, highest, step], labelled only at the ends.
const ANCHORED = { anchored5: [1, 5, 1], anchored7: [1, 7, 1], tlx21: [0, 100, 5] };

function likertItem(item, index) {
  const name = `q-${item.id}`;
  const anchored = ANCHORED[item.kind];
  let scale;
  if (anchored) {
    const [low, high, step] = anchored;
    scale = Array.from({ length: (high - low) / step + 1 }, (_, i) => [low + i * step, String(low + i * step)]);
  } else if (item.kind === "likert5" || item.kind === "attention") { // an attention check looks like any item
    scale = LIKERT.map((label, i) => [i + 1, label]);
  } else {
    scale = Array.from({ length: 10 }, (_, i) => [i + 1, String(i + 1)]);
  }
  const [lowLabel, highLabel] = item.anchors ?? ["", ""];
  const legendId = `legend-${item.id}`;
  // A mark's accessible name says where it lies between the ends ("1 of 5, Fake"), not just its number.
  const named = (value, label) => (anchored
    ? `${label}${value === anchored[0] ? `, ${lowLabel}` : value === anchored[1] ? `, ${highLabel}` : ""}` : null);
  return h("fieldset", { class: `item ${item.kind}${anchored ? " anchored" : ""}` },
    h("legend", { id: legendId }, `${index + 1}. ${item.text}`, item.required ? "" : " (optional)"),
    anchored ? h("div", { class: "anchors", "aria-hidden": "true" }, h("span", {}, lowLabel), h("span", {}, highLabel)) : null,
    h("div", { class: "scale" }, scale.map(([value, label]) =>
      h("label", { title: named(value, label) },
        h("input", { type: "radio", name, value: String(value), required: item.required,
          "aria-label": named(value, label) }),
        h("span", {}, label)))));
}

export function questionnaireView(state, { onSubmit, onPaste, pending }) {
  const items = state.questionnaire || [];
  const form = h("form", { class: "questionnaire", novalidate: true },
    items.map((item, i) => item.kind === "text"
      ? h("fieldset", { class: "item text" }, h("legend", {}, `${i + 1}. ${item.text}`, item.required ? "" : " (optional)"),
        h("textarea", { name: `q-${item.id}`, rows: "3", maxlength: "5000", "aria-label": item.text,
          onpaste: () => onPaste?.(item.id) }))
      : likertItem(item, i)),
    h("p", { class: "error", id: "form-error", role: "alert" }),
    h("div", { class: "buttons" }, h("button", { class: "primary", type: "submit", disabled: pending }, "Submit answers")));
  form.addEventListener("submit", (event) => {
    event.preventDefault();
    const answers = {};
    const missing = [];
    for (const item of items) {
      const field = form.elements[`q-${item.id}`];
      let value = item.kind === "text" ? field.value.trim() : (field.value ? Number(field.value) : null);
      if (value === "" || value === null) value = null;
      if (value === null && item.required) missing.push(item);
      answers[item.id] = value;
    }
    const error = form.querySelector("#form-error");
    if (missing.length) {
      error.textContent = `Please answer question ${missing.map((m) => items.indexOf(m) + 1).join(", ")}.`;
      return;
    }
    error.textContent = "";
    onSubmit(answers);
  });
  return h("section", { class: "card narrow" },
    heading("A few questions"),
    h("p", {}, "Thank you for teaching the robot. Please tell us how it went."),
    form);
}

/** The completion code with a button that copies it (`onCopy(code)`), and a line for what the copy did. */
export function codeBlock(code, onCopy) {
  return h("div", { class: "code-block" },
    h("p", { class: "code", id: "completion-code" }, code),
    h("button", { type: "button", id: "copy-code", onclick: () => onCopy(code) }, "Copy the code"),
    h("span", { id: "copy-note", class: "hint", role: "status" }));
}

/** The last page: the completion code, what the robot learned in plain words, and the way back (counting down). */
export function doneView(state, { secondsLeft, onCopy }) {
  const { code, redirect_url: url, learned } = state.completion;
  return h("section", { class: "card narrow" },
    heading("Thank you!"),
    h("p", {}, "You have finished the study. Your completion code is:"),
    codeBlock(code, onCopy),
    learned?.length ? h("div", { class: "summary" }, h("p", {}, "What the robot learned from you:"),
      h("ul", {}, learned.map((t) => h("li", {}, h("strong", {}, `Task ${t.task_index + 1}: `),
        t.summary || `${t.map_description}.`)))) : null,
    url ? h("p", {}, secondsLeft === null
      ? "You can go back to the study platform now. "
      : h("span", { class: "countdown", id: "countdown", "aria-live": "polite" },
        `You will be taken back in ${secondsLeft} second${secondsLeft === 1 ? "" : "s"}. `),
    h("a", { href: url, id: "redirect", class: "button primary" }, "Go back now"))
      : h("p", {}, "You can close this page now."),
    consentCopy(state));
}

/** The information sheet agreed to, to read again or print, at the end. */
export function consentCopy(state) {
  if (!state.consent?.given_at) return null;
  return h("details", { class: "reminder consent-copy", id: "consent-copy" },
    h("summary", {}, "The study information you agreed to (to print or keep)"),
    consentSheet(state),
    h("div", { class: "buttons no-print" }, printButton()));
}

export function withdrawnView() {
  return h("section", { class: "card narrow" }, heading("You chose not to take part"),
    h("p", {}, "Nothing more will be recorded. You can close this page."));
}

export function elsewhereView({ onTakeOver }) {
  return h("section", { class: "card narrow", id: "elsewhere" },
    heading("This study is open in another tab"),
    h("p", {}, "You can only work on the study in one tab or window at a time. Please continue in the other tab, ",
      "or close it: this page then continues by itself within a few seconds."),
    h("div", { class: "buttons" }, h("button", { onclick: onTakeOver }, "Use this tab instead")));
}
