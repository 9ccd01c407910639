// A library's first page on the page (the .tact and games panels): each entry a list item
// with its name in bold, a one-line summary and one button; a line when the library is
// empty, and one saying where the rest is when the page is full.

const $ = (id) => document.getElementById(id);

// Entries asked for and shown at the most.
export const LIST_LIMIT = 20;

// One entry's list item. `data` is set on the item's dataset ({name: "Stab_ArmL"}); the
// button is {label, ariaLabel, onClick}.
export function libraryItem(data, title, summaryText, button) {
  const li = document.createElement("li");
  Object.assign(li.dataset, data);
  const text = document.createElement("div");
  text.className = "library-text";
  const name = document.createElement("strong");
  name.textContent = title;
  const summary = document.createElement("span");
  summary.textContent = summaryText;
  text.append(name, summary);
  const buttons = document.createElement("div");
  buttons.className = "library-buttons";
  const action = document.createElement("button");
  action.type = "button";
  action.className = "secondary small";
  action.textContent = button.label;
  action.setAttribute("aria-label", button.ariaLabel);
  action.addEventListener("click", button.onClick);
  buttons.appendChild(action);
  li.append(text, buttons);
  return li;
}

// Show a page of list items in `${prefix}-list`, with `${prefix}-empty` shown when there
// is none and `${prefix}-more` (its text `more`) when the page is full.
export function showPage(prefix, items, more) {
  $(`${prefix}-list`).replaceChildren(...items);
  $(`${prefix}-empty`).hidden = items.length > 0;
  $(`${prefix}-more`).textContent = more;
  $(`${prefix}-more`).hidden = items.length < LIST_LIMIT;
}
