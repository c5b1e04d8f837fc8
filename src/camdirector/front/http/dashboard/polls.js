// The polls: each runs every so often while someone is logged in, and all of them at once right
// after a login; one still running when its time comes again is not started twice. A poll's
// failure shows in the header.
import { refreshJobs } from "./jobs.js";
import { refreshSession } from "./session.js";
import { refreshSessions } from "./sessions.js";
import { state } from "./state.js";
import { loadDirectors } from "./style.js";
import { showTrouble } from "./trouble.js";

export const POLL_SESSIONS_MS = 1000;   // the session list and the jobs (and the directors, until they came)
const POLL_SESSION_MS = 500;            // the selected session's frames

const POLLS = [
  [POLL_SESSIONS_MS, refreshSessions],
  [POLL_SESSIONS_MS, refreshJobs],
  [POLL_SESSION_MS, refreshSession],
  [POLL_SESSIONS_MS, loadDirectors],
];

const running = new Set();   // the polls whose last run has not ended: a slow server is not asked again meanwhile

function run(task) {
  if (!state.caller || running.has(task)) return;
  running.add(task);
  task().catch(showTrouble).finally(() => running.delete(task));
}

export function startPolls() {
  for (const [ms, task] of POLLS) setInterval(() => run(task), ms);
}

export function pollNow() {
  for (const [, task] of POLLS) run(task);
}
