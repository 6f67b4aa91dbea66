// Small pieces every dashboard screen uses: pills, the toast, error boxes, breadcrumbs, times, file downloads and
// the server's per-field messages. All text from the server goes through textContent, never innerHTML.

import { ApiError } from "./dashboard-api.js";
import { h } from "./dom.js";

export function pill(text, kind = text) {
  return h("span", { class: `pill pill-${kind}` }, text);
}

export function toast(message, kind = "info") {
  const el = document.getElementById("toast");
  el.textContent = message;
  el.className = `toast-${kind}`;
  el.hidden = false;
  clearTimeout(toast.timer);
  toast.timer = setTimeout(() => { el.hidden = true; }, 3500);
}

export function errorBox(error) {
  return h("div", { class: "error", role: "alert" }, error instanceof ApiError ? error.detail : String(error));
}

export function setCrumbs(...items) {
  const crumbs = document.getElementById("crumbs");
  crumbs.replaceChildren(...items.flatMap((item, i) => [...(i ? [h("span", { class: "sep" }, "/")] : []),
    item.href ? h("a", { href: item.href }, item.text) : h("span", {}, item.text)]));
}

/** Local time as YYYY-MM-DD HH:MM (compact and unambiguous). */
export function when(iso) {
  if (!iso) return "–";
  const d = new Date(iso);
  const two = (n) => String(n).padStart(2, "0");
  return `${d.getFullYear()}-${two(d.getMonth() + 1)}-${two(d.getDate())} ${two(d.getHours())}:${two(d.getMinutes())}`;
}

/** Save a blob as a file (the data came with the token, so a plain link could not fetch it). */
export function saveBlob(filename, blob) {
  const url = URL.createObjectURL(blob);
  const a = h("a", { href: url, download: filename, hidden: true });
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10_000);
}

/** Put each of the server's {field, message} next to the input with that data-field (the rest in `box`);
 * no error clears them. */
export function showFieldErrors(form, box, error) {
  for (const slot of form.querySelectorAll("[data-error-for]")) slot.textContent = "";
  for (const input of form.querySelectorAll("[aria-invalid]")) input.removeAttribute("aria-invalid");
  if (!error) {
    box.replaceChildren();
    return;
  }
  const rest = [];
  for (const e of error instanceof ApiError && error.errors ? error.errors : []) {
    const slot = form.querySelector(`[data-error-for="${CSS.escape(e.field)}"]`);
    if (slot) {
      slot.textContent = e.message;
      form.querySelector(`[data-field="${CSS.escape(e.field)}"]`)?.setAttribute("aria-invalid", "true");
    } else {
      rest.push(e);
    }
  }
  const listed = error instanceof ApiError && error.errors;
  box.replaceChildren(...(listed && !rest.length ? [] : [listed
    ? h("div", { class: "error", role: "alert" }, h("ul", {}, rest.map((e) => h("li", {}, `${e.field}: ${e.message}`))))
    : errorBox(error)]));
}

/** A labelled input with a slot for the server's message about it (data-field = the API's name for it). */
export function field(label, input, name) {
  input.dataset.field = name;
  return h("label", { class: "field" }, label, input, h("span", { class: "field-error", "data-error-for": name }));
}
