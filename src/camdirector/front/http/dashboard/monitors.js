// The monitors: the program's live stream and the last cut's before and after, from
// /v1/sessions/{id}/view.mjpeg and /view. A browser keeps about six connections per host and a
// live MJPEG stream holds one for as long as it runs: the program monitor alone streams, the others
// are single pictures.
import { send, sessionPath } from "./api.js";
import { state } from "./state.js";

export const MONITOR_WIDTH_PX = 320;   // the pictures' width (the server's default); the height follows the lens
const PROGRAM_FPS = 4;                 // the program monitor's live stream, pictures a second

export function watch(sessionId) {   // the monitors of a newly selected session: its live stream, the others emptied
  const program = document.getElementById("program-view");
  // Set only here, never on a poll: each new src would open another stream.
  program.src = `${sessionPath(sessionId)}/view.mjpeg?fps=${PROGRAM_FPS}&width=${MONITOR_WIDTH_PX}`;
  document.getElementById("program-view-status").textContent = "";
  state.cutShown = null;
  for (const id of ["cut-before", "cut-after"]) document.getElementById(id).removeAttribute("src");
  document.getElementById("cut-caption").textContent = "No cut yet.";
  state.candidatesShown = "";
  state.candidatesPictured = { frame: null, ms: 0 };
  document.querySelector("#candidates tbody").replaceChildren();
}

export function programStopped() {   // the stream ended (the session did) or was refused (too many streams)
  document.getElementById("program-view-status").textContent =
    "The live view stopped: the session ended, or the server serves its maximum of live views.";
}

async function picture(url) {   // a monitor's picture as an object URL, with the headers saying what it shows
  const reply = await send(url);
  return { url: URL.createObjectURL(await reply.blob()), frame: reply.headers.get("X-Camdirector-Frame"),
           placeholder: reply.headers.get("X-Camdirector-Placeholder") };
}

// The last cut's before and after, asked for when a newer cut appears in the frames (and once per
// session, for a cut older than the frames kept). Fetched rather than set as src: the headers say
// which cut the server holds (the session's first pose is a cut with nothing before it).
export async function showLastCut(frames) {
  const sessionId = state.selected;
  const cuts = frames.filter((f) => f.cut && f.camera);
  const newest = cuts.length ? cuts[cuts.length - 1].frame : "none";
  const key = `${sessionId} ${newest}`;
  if (key === state.cutShown) return;
  state.cutShown = key;
  // The cut's frame in the address: a new picture per cut, never a cached one.
  const base = `${sessionPath(sessionId)}/view?width=${MONITOR_WIDTH_PX}&frame=${newest}&shot=`;
  let before, after;
  try {
    [before, after] = await Promise.all([picture(base + "cut_before"), picture(base + "cut_after")]);
  } catch (error) {
    if (state.cutShown === key) state.cutShown = null;   // asked again on the next poll
    return;
  }
  if (state.cutShown !== key) {   // another session was picked, or a newer cut asked for, meanwhile
    URL.revokeObjectURL(before.url);
    URL.revokeObjectURL(after.url);
    return;
  }
  state.cutPictures.forEach((url) => URL.revokeObjectURL(url));
  state.cutPictures = [before.url, after.url];
  document.getElementById("cut-before").src = before.url;
  document.getElementById("cut-after").src = after.url;
  document.getElementById("cut-caption").textContent = cutCaption(before, after, frames);
}

function cutCaption(before, after, frames) {
  if (after.placeholder) return `Nothing to show: ${after.placeholder}.`;
  const cut = frames.find((f) => String(f.frame) === after.frame);
  const why = cut ? [cut.shot ? cut.shot.reason : null, ...cut.flags].filter(Boolean) : [];
  return `Cut at frame ${after.frame} (from frame ${before.frame})` +
    (cut ? ` to shot ${cut.shot_id}: ${why.length ? why.join(", ") : "new shot"}.` : ".");
}
