// The participant page's study-operations screens, kept apart from participant-views.js: the comprehension
// quiz, the "Withdraw" link (on every page after consent, with a confirmation) and the pages shown when a
// participant leaves early (declined consent, withdrew, screened out), with the study's redirect.
// Functions from (state, handlers) to DOM nodes; participant.js owns the state and the calls.

import { h } from "./dom.js";
import { codeBlock, instructionsBody } from "./participant-views.js";

const REASONS = {
  declined_consent: ["You chose not to take part", "Nothing more will be recorded."],
  withdrew: ["You have withdrawn from the study",
    "Your recorded actions and answers have been deleted. If you joined through Prolific, please return the study there."],
  comprehension: ["Thank you for your interest",
    "Some answers about how the study works were not right, so the study ends here for you."],
  timeout: ["This session has ended", "You were away longer than this study allows, so it has ended for you."],
};

/** Load this module's style sheet once (the page's policy allows style sheets from this server only). */
export function installStyles(assetUrl) {
  if (document.getElementById("study-ops-css")) return;
  document.head.append(h("link", { rel: "stylesheet", id: "study-ops-css", href: assetUrl("participant-study-ops.css") }));
}

function heading(text) {
  return h("h1", { tabindex: "-1", class: "focus-target" }, text);
}

/** One quiz question as a radio group with no option chosen by focus alone: each option is a checkbox (Tab stops
 * on every option; Space or a click chooses it and unchecks the others), so neither Tab nor the arrow keys pick
 * an answer the participant did not choose. `chosen` is the option kept from the last attempt. */
function choiceGroup(item, index, chosen, wrong) {
  const legendId = `quiz-q-${item.id}`;
  const boxes = item.options.map((option, j) => h("input", {
    type: "checkbox", class: "choice", name: `quiz-${item.id}`, value: String(j), checked: chosen === j,
  }));
  boxes.forEach((box) => box.addEventListener("change", () => {
    for (const other of boxes) if (other !== box) other.checked = false;
  }));
  return h("fieldset", { class: wrong ? "item wrong" : "item", "data-item": item.id },
    h("legend", { id: legendId }, `${index + 1}. ${item.text} `, h("span", { class: "hint" }, "(choose one)")),
    wrong ? h("p", { class: "wrong-note", id: `quiz-wrong-${item.id}` }, "This answer was not right. Please read the "
      + "question again.") : null,
    h("div", { class: "choices" },
    item.options.map((option, j) => h("label", {}, boxes[j], h("span", {}, option)))));
}

/** The comprehension quiz: one group of choices per question; all must be answered. After a failed attempt the
 * answers stay, the questions answered wrongly are marked (unless the study hides it), and the instructions can
 * be read again. */
export function quizView(state, { onQuiz, pending }) {
  const { items, failed_attempts: failed, attempts_left: left } = state.quiz;
  const kept = state.quiz.answers || {};
  const wrong = state.quiz.wrong; // null: the study does not say which
  const form = h("form", { class: "questionnaire quiz", novalidate: true },
    items.map((item, i) => choiceGroup(item, i, kept[item.id], Boolean(wrong?.includes(item.id)))),
    h("p", { class: "error", id: "quiz-error", role: "alert" }),
    h("div", { class: "buttons" }, h("button", { class: "primary", type: "submit", disabled: pending }, "Check my answers")));
  form.addEventListener("submit", (event) => {
    event.preventDefault();
    const answers = {};
    const missing = [];
    items.forEach((item, i) => {
      const box = form.querySelector(`input[name="quiz-${item.id}"]:checked`);
      if (!box) missing.push(i + 1);
      else answers[item.id] = Number(box.value);
    });
    if (missing.length) {
      form.querySelector("#quiz-error").textContent = `Please answer question ${missing.join(", ")}.`;
      return;
    }
    onQuiz(answers);
  });
  const numbers = (wrong || []).map((id) => items.findIndex((item) => item.id === id) + 1).filter((n) => n > 0);
  const which = numbers.length
    ? `The answer${numbers.length > 1 ? "s" : ""} to question${numbers.length > 1 ? "s" : ""} ${numbers.join(", ")} `
      + `${numbers.length > 1 ? "were" : "was"} not right. `
    : "Some answers were not right. ";
  return h("section", { class: "card narrow" },
    heading("A few questions before you start"),
    h("p", {}, "Please check that the instructions were clear."),
    failed ? h("div", { class: "notice", id: "quiz-retry" },
      h("p", {}, which, left === 1 ? "This is your last try." : `You have ${left} tries left.`),
      h("p", {}, "Your answers are kept; change the ones you want.")) : null,
    h("details", { class: "reminder", id: "quiz-instructions", open: Boolean(failed) },
      h("summary", {}, "Read the instructions again"), instructionsBody(state)),
    form);
}

/** The page after leaving early: why, and the way back to Prolific when the study set one (counting down from
 * `secondsLeft`, as on the done page; null: no countdown). After withdrawing, a link back to the study platform. */
export function endedView(state, { secondsLeft, onCopy }) {
  const completion = state.completion ?? {};
  const [title, text] = REASONS[completion.reason] ?? REASONS.declined_consent;
  const url = completion.redirect_url;
  const back = completion.return_url;
  return h("section", { class: "card narrow", id: "ended" },
    heading(title),
    h("p", {}, text),
    completion.code ? h("p", {}, "Your code:") : null,
    completion.code ? codeBlock(completion.code, onCopy) : null,
    url ? h("p", {}, secondsLeft === null
      ? "You can go back to the study platform now. "
      : h("span", { class: "countdown", id: "countdown", "aria-live": "polite" },
        `You will be taken back in ${secondsLeft} second${secondsLeft === 1 ? "" : "s"}. `),
    h("a", { href: url, id: "redirect", class: "button primary" }, "Go back now"))
      : back ? h("p", {}, h("a", { href: back, id: "return-link", class: "button primary" }, "Go back to the study platform"))
        : h("p", {}, "You can close this page now."));
}

/** The "are you still there?" dialog before an idle time-out; `onStay` answers it. */
export function idleDialog(onStay) {
  const dialog = h("dialog", { id: "idle-dialog", "aria-labelledby": "idle-title" },
    h("h2", { id: "idle-title" }, "Are you still there?"),
    h("p", {}, "Nothing has happened for a while. This session ends in ", h("strong", { id: "idle-seconds" }, ""),
      " unless you say you are still here."),
    h("div", { class: "buttons" }, h("button", { class: "primary", id: "still-here", onclick: onStay }, "I am still here")));
  document.body.append(dialog);
  return dialog;
}

/** Whether the page offers withdrawal now: after consent, until the participant has left. */
export function canWithdraw(state) {
  return Boolean(state?.consent?.given_at) && !["withdrawn", "screened_out"].includes(state.stage);
}

/** The "Withdraw" link in the page's top bar, with a confirmation dialog; hidden where it does not apply. */
export function syncWithdrawLink(state, { onWithdraw, pending }) {
  const bar = document.querySelector(".topbar");
  if (!bar) return;
  let link = document.getElementById("withdraw-link");
  if (!link) {
    const dialog = h("dialog", { id: "withdraw-dialog" },
      h("h2", {}, "Withdraw from the study?"),
      h("p", {}, "If you withdraw, everything recorded about your session (your actions and answers) is deleted, and ",
        "you cannot continue. You do not have to give a reason."),
      h("div", { class: "buttons" },
        h("button", { id: "withdraw-confirm", class: "danger", onclick: () => { dialog.close(); onWithdraw(); } },
          "Yes, withdraw and delete my data"),
        h("button", { id: "withdraw-cancel", class: "primary", onclick: () => dialog.close() }, "No, continue the study")));
    link = h("button", { id: "withdraw-link", type: "button", class: "withdraw-link",
      onclick: () => (dialog.showModal ? dialog.showModal() : dialog.setAttribute("open", "")) }, "Withdraw");
    bar.append(link);
    document.body.append(dialog);
  }
  link.hidden = !canWithdraw(state);
  link.disabled = Boolean(pending);
}
