// A human's take in a match: POST /v1/sessions/{id}/take puts a shot on the program, held until
// released (docs/protocol.md); the result shows by the release button.
import { api, sessionPath } from "./api.js";
import { playerNames } from "./names.js";
import { state } from "./state.js";

export function describeShot(shot) {   // with the players' names: show it as text
  const who = shot.subject_ids.length ? playerNames(shot.subject_ids) : "the map";
  // a replay says which kill it shows again (worker/timeline.py: shot.replay)
  const kill = shot.replay ? ` (the kill at ${shot.replay.kill_time_s.toFixed(1)} s)` : "";
  return `${shot.kind.replace("SHOT_", "")} ${who}${kill}`;
}

export async function take(body) {   // { subject_ids, kind } to take a shot, { release: true } to release it
  const result = document.getElementById("take-result");
  try {
    const reply = await api(`${sessionPath(state.selected)}/take`, {
      method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body),
    });
    result.className = "ok";
    result.textContent = reply.shot ? `taken: ${describeShot(reply.shot)}, held until released` : "released";
  } catch (error) {
    result.className = "error";
    result.textContent = error.message;
  }
}
