// One monitor per candidate shot of a match, its take button under it. The rows are rebuilt only
// when the shots offered change, so that a button does not move under the pointer between polls;
// their reasons and interest are rewritten in place, and their pictures asked anew about once a second.
import { sessionPath } from "./api.js";
import { cell } from "./cells.js";
import { MONITOR_WIDTH_PX } from "./monitors.js";
import { playerNames, withNames } from "./names.js";
import { gate } from "./roles.js";
import { state } from "./state.js";
import { take } from "./takes.js";

const CANDIDATE_REFRESH_MS = 1000;   // candidate pictures: about once a second, not on every poll

export function showCandidates(candidates, frame) {
  const body = document.querySelector("#candidates tbody");
  const key = JSON.stringify(candidates.map((c) => [c.shot.kind, c.shot.subject_ids]));
  if (key !== state.candidatesShown) {
    state.candidatesShown = key;
    const kept = new Map([...body.rows].map((row) => [row.dataset.key, row]));   // their pictures stay
    body.replaceChildren(...candidates.map((c) => kept.get(candidateKey(c)) || candidateRow(c)));
    state.candidatesPictured = { frame: null, ms: 0 };   // a new monitor gets its picture now
  }
  candidates.forEach((c, i) => {
    const row = body.rows[i];
    row.querySelector(".candidate-why").textContent = withNames(c.shot.reason);
    row.querySelector(".candidate-interest").textContent = `interest ${c.score.toFixed(2)}`;
  });
  const now = Date.now();
  if (frame === state.candidatesPictured.frame || now - state.candidatesPictured.ms < CANDIDATE_REFRESH_MS) return;
  state.candidatesPictured = { frame, ms: now };
  for (const img of body.querySelectorAll("img")) {   // the frame in the address: a new picture, not the cached one
    img.src = `${sessionPath(state.selected)}/view?shot=candidate&subjects=${encodeURIComponent(img.dataset.subjects)}` +
      `&width=${MONITOR_WIDTH_PX}&frame=${frame}`;
  }
}

function candidateKey(c) {
  return `${c.shot.kind} ${c.shot.subject_ids.join(",")}`;
}

function candidateRow(c) {
  const row = document.createElement("tr");
  row.dataset.key = candidateKey(c);
  row.dataset.subjects = c.shot.subject_ids.join(",");
  const img = document.createElement("img");
  img.className = "monitor";
  img.alt = `what the candidate shot of ${playerNames(c.shot.subject_ids)} would show`;
  img.dataset.testid = "candidate-view";
  img.dataset.subjects = row.dataset.subjects;
  const monitor = cell(row, "");
  monitor.className = "candidate-monitor";
  monitor.appendChild(img);
  cell(row, c.shot.kind.replace("SHOT_", "")).className = "candidate-kind";
  cell(row, playerNames(c.shot.subject_ids)).className = "candidate-players";
  cell(row, "").className = "candidate-why";
  cell(row, "").className = "candidate-interest";
  const button = document.createElement("button");
  button.textContent = "take";
  gate(button, "session.take");
  button.addEventListener("click", () => take({ subject_ids: c.shot.subject_ids, kind: c.shot.kind }));
  cell(row, "").appendChild(button);
  return row;
}
