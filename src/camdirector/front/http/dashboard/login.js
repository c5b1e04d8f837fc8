// Who is logged in. With authentication on, the page is shown a key once, in the login form:
// /v1/login answers with the login cookie (HttpOnly: no script here reads it), and the key itself
// is kept nowhere, not in storage, the address or the form. Without authentication (`--no-auth`)
// /v1/whoami answers at once and no form is shown. A logout, or a 401 on any request, brings the
// form back and forgets what the page showed of the last key's tenant.
import { ApiError, api } from "./api.js";
import { POLL_SESSIONS_MS, pollNow } from "./polls.js";
import { applyRole } from "./roles.js";
import { state } from "./state.js";
import { showTrouble } from "./trouble.js";

function loggedIn(who) {
  state.caller = who;
  document.getElementById("login-panel").hidden = true;
  document.getElementById("login-result").textContent = "";
  document.getElementById("dashboard").hidden = false;
  document.getElementById("who").textContent = who.key_id === null
    ? "authentication off: every caller is an admin of tenant default"
    : `${who.role} of tenant ${who.tenant} (key ${who.key_id})`;
  document.getElementById("logout").hidden = who.key_id === null;
  applyRole();
  pollNow();
}

// What the page showed of the last key's sessions and jobs: the next key may be another tenant's.
function forget() {
  state.selected = null;
  state.styleSentBySession = {};
  state.buffered = { session: null, frames: [], events: [] };
  state.topViews = {};
  state.candidatesShown = "";
  document.getElementById("session-panel").hidden = true;
  document.getElementById("program-view").removeAttribute("src");   // ends its live stream
  document.getElementById("take-result").textContent = "";
  document.getElementById("job-view").hidden = true;
  for (const id of ["sessions", "candidates", "jobs"]) document.querySelector(`#${id} tbody`).replaceChildren();
}

export function showLogin(message, className = "error") {
  state.caller = null;
  forget();
  document.getElementById("dashboard").hidden = true;
  document.getElementById("health").textContent = "not logged in";
  document.getElementById("who").textContent = "";
  document.getElementById("logout").hidden = true;
  document.getElementById("login-panel").hidden = false;
  const result = document.getElementById("login-result");
  result.className = className;
  result.textContent = message;
  document.querySelector('#login-form input[name="key"]').focus();
}

export async function logIn(event) {
  event.preventDefault();
  const input = event.target.key;
  const key = input.value;
  input.value = "";   // the key is not kept, not even in the form: the cookie stands for it
  try {
    loggedIn(await api("/v1/login", {
      method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify({ key }),
    }));
  } catch (error) {
    showLogin(error instanceof ApiError ? error.detail : `unreachable: ${error.message}`);
  }
}

export async function logOut() {
  try {
    await api("/v1/logout", { method: "POST" });
    showLogin("Logged out.", "ok");
  } catch (error) {
    showTrouble(error);
  }
}

export async function identify() {   // who the login cookie makes the caller, or the open server's admin
  try {
    loggedIn(await api("/v1/whoami"));
  } catch (error) {
    showTrouble(error);
    if (!(error instanceof ApiError && error.status === 401)) setTimeout(identify, POLL_SESSIONS_MS);
  }
}
