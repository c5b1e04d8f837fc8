// Why the camera moved: the newest frame's flags, then every cut's in the window with its shot's
// reason (its players by name), and the scores the rig gave (docs/protocol.md).
import { withNames } from "./names.js";

export function showWhy(frames) {
  const list = document.getElementById("why");
  list.replaceChildren();
  if (!frames.length) return;
  const last = frames[frames.length - 1];
  const add = (text) => {
    const li = document.createElement("li");
    li.textContent = text;
    list.appendChild(li);
  };
  add(`frame ${last.frame}: ${last.flags.length ? last.flags.join(", ") : "on its preferred path (no flag)"}` +
      scored(last.scores));
  for (const f of frames.filter((f) => f.cut).reverse()) {
    const why = [f.shot ? withNames(f.shot.reason) : null, ...f.flags].filter(Boolean);
    add(`cut at frame ${f.frame} to shot ${f.shot_id}: ${why.length ? why.join(", ") : "new shot"}` +
        scored(f.scores));
  }
}

function scored(scores) {   // TRACKS: the sub-scores of the target it chose and their total; MATCH: the shot's
  const names = Object.keys(scores || {}).filter((k) => k !== "total");
  if (!names.length) return "";
  const parts = names.map((k) => `${k.replaceAll("_", " ")} ${scores[k].toFixed(2)}`);
  return "total" in scores ? `; target scored ${parts.join(", ")}: total ${scores.total.toFixed(2)}`
    : `; scored ${parts.join(", ")}`;
}
