// The session list: the state.caller's tenant's sessions (GET /v1/sessions) with the node's health in
// the header, and the choice of one to watch.
import { api } from "./api.js";
import { cell } from "./cells.js";
import { watch } from "./monitors.js";
import { refreshSession } from "./session.js";
import { state } from "./state.js";

export async function refreshSessions() {
  const health = await api("/healthz");
  const who = state.caller;
  const { sessions } = await api("/v1/sessions");
  if (state.caller !== who) return;   // logged out meanwhile: the list was the last key's
  // The tenant's sessions (the list's), not /healthz's count of the whole node's.
  document.getElementById("health").textContent =
    `${health.status}: ${sessions.length} sessions of tenant ${state.caller.tenant}, ${health.workers} workers`;
  const body = document.querySelector("#sessions tbody");
  body.replaceChildren();
  for (const s of sessions) {
    const row = document.createElement("tr");
    row.dataset.session = s.session_id;
    row.classList.toggle("selected", s.session_id === state.selected);
    cell(row, s.session_id.slice(0, 12));
    cell(row, s.worker);
    cell(row, s.frames);
    cell(row, s.streams);
    cell(row, s.idle_s.toFixed(1));
    cell(row, s.transports.join(", "));
    row.addEventListener("click", () => select(s.session_id));
    body.appendChild(row);
  }
  document.getElementById("no-sessions").hidden = sessions.length > 0;
  for (const id of Object.keys(state.topViews)) {   // an ended session's top view is not needed again
    if (!sessions.some((s) => s.session_id === id)) delete state.topViews[id];
  }
  if (state.selected && !sessions.some((s) => s.session_id === state.selected)) {
    document.getElementById("shot-summary").textContent = "the session has ended";
  }
}

function select(sessionId) {
  const changed = sessionId !== state.selected;
  state.selected = sessionId;
  document.getElementById("session-panel").hidden = false;
  document.getElementById("session-id").textContent = sessionId;
  document.getElementById("style-result").textContent = "";
  for (const row of document.querySelectorAll("#sessions tbody tr")) {
    row.classList.toggle("selected", row.dataset.session === sessionId);
  }
  if (changed) watch(sessionId);
  refreshSession();
}
