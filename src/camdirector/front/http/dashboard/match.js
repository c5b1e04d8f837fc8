// A match session's program: the shot on it (the director's, or a human's take held until
// released), the cut the director plans (with a broadcast delay), the candidates and the game's
// events at the program's moments, the players by name (names.js).
import { showCandidates } from "./candidates.js";
import { playerName, withNames } from "./names.js";
import { describeShot } from "./takes.js";

export function showMatch(frames, events) {
  const last = frames[frames.length - 1];
  const match = Boolean(last && last.players);
  document.getElementById("match-view").hidden = !match;
  document.getElementById("match-caption").hidden = !match;
  if (!match) return;
  const program = document.getElementById("program-shot");
  // The match rig starts the reason of a human's shot, and of its fallback, with "take".
  const held = Boolean(last.shot && last.shot.held);
  program.textContent = last.buffering || !last.shot ? "buffering: the broadcast delay is filling, no camera yet"
    : `${describeShot(last.shot)} (${held ? "held" : "the director's"}): ${withNames(last.shot.reason)}`;
  program.classList.toggle("held", held);
  document.getElementById("release").hidden = !held;
  const cut = last.planned_cut;
  document.getElementById("planned-cut").textContent = cut
    ? `in ${(cut.time_s - last.time_s).toFixed(1)} s (at ${cut.time_s.toFixed(1)} s) to ${describeShot(cut.shot)}: ` +
      withNames(cut.shot.reason)
    : held ? "none while a take is held" : "none: the director decides as the game goes (a delay shows what it plans)";
  showCandidates(last.candidates, last.frame);
  const log = document.getElementById("event-log");
  log.replaceChildren(...events.slice().reverse().map((e) => {
    const li = document.createElement("li");
    const who = e.other_actor_id ? `${playerName(e.actor_id)} → ${playerName(e.other_actor_id)}` : playerName(e.actor_id);
    li.textContent = `${e.time_s.toFixed(2)} s ${e.kind.replace("EVENT_", "").toLowerCase()} ${who}` +
      (e.label ? `: ${e.label}` : "");
    return li;
  }));
}
