// The director's dashboard, the page's entry module (ES modules, no build step). Reads the REST API
// only: /healthz, /v1/sessions, /v1/sessions/{id}, PUT /v1/sessions/{id}/style, POST
// /v1/sessions/{id}/take (a MATCH session's take and release), the monitors'
// /v1/sessions/{id}/view, view.mjpeg and topview.png, /v1/overview-jobs, /v1/match-directors (the
// style form's director options); and who the caller is, /v1/whoami, /v1/login and /v1/logout
// (docs/security.md). Data is written with textContent, never as HTML.
//
// With authentication on, the page is shown a key once, in the login form: /v1/login answers with
// the login cookie (HttpOnly: no script here reads it), and the key itself is kept nowhere, not in
// storage, the address or the form. Every request then goes with the cookie; one that changes
// anything carries the CSRF token the login gave. Without authentication (`--no-auth`) /v1/whoami
// answers at once and no form is shown.
//
// One module per idea, sharing what they show in state.js: api.js (every request, auth and CSRF),
// login.js and roles.js (who is logged in, what their role may do), polls.js, sessions.js (the list),
// session.js (the selected session) with monitors.js, topview.js, timeline.js (with framing.js),
// why.js, match.js, candidates.js and takes.js, style.js, jobs.js. This one wires the page's
// controls to them and starts.
import { onUnauthorized } from "./api.js";
import { FRAMING_LOST } from "./framing.js";
import { submitOverview } from "./jobs.js";
import { identify, logIn, logOut, showLogin } from "./login.js";
import { programStopped } from "./monitors.js";
import { startPolls } from "./polls.js";
import { refreshSession } from "./session.js";
import { applyStyle } from "./style.js";
import { take } from "./takes.js";

onUnauthorized(showLogin);
for (const threshold of document.querySelectorAll(".framing-lost")) threshold.textContent = FRAMING_LOST;
document.getElementById("style-form").addEventListener("submit", async (event) => {
  if (await applyStyle(event)) refreshSession();
});
document.getElementById("release").addEventListener("click", () => take({ release: true }));
document.getElementById("overview-form").addEventListener("submit", submitOverview);
document.getElementById("program-view").addEventListener("error", programStopped);
document.getElementById("login-form").addEventListener("submit", logIn);
document.getElementById("logout").addEventListener("click", logOut);
startPolls();
identify();
