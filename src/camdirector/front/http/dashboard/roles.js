// The verbs the dashboard's controls use and what each control does. Whether the caller's key
// has a verb comes from /v1/whoami (its role's verbs, access/roles.py); only to switch a control
// off beforehand and say why: the server decides, and a refusal shows where the control's result does.
import { state } from "./state.js";

export const CONTROLS = {
  "session.take": "take and release shots",
  "session.style": "change a session's style",
  "job.submit": "submit overview jobs",
};

function may(verb) {
  return state.caller.verbs.includes(verb);
}

export function gate(button, verb) {   // a control the caller's role may not use: off, saying why as the server would
  button.disabled = !may(verb);
  button.title = may(verb) ? "" : `a key of role '${state.caller.role}' may not ${verb} (docs/security.md)`;
}

export function applyRole() {
  gate(document.getElementById("release"), "session.take");
  gate(document.querySelector('#style-form button[type="submit"]'), "session.style");
  gate(document.querySelector('#overview-form button[type="submit"]'), "job.submit");
  const refused = Object.keys(CONTROLS).filter((verb) => !may(verb));
  const note = document.getElementById("role-note");
  note.hidden = refused.length === 0;
  note.textContent = `A key of role '${state.caller.role}' may not ${refused.map((verb) => CONTROLS[verb]).join(", ")}: ` +
    "those buttons are off (docs/security.md).";
}
