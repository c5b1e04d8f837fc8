// The monitors: the program's live stream and the last cut's before and after, from
// /v1/sessions/{id}/view.mjpeg and /view. A browser keeps about six connections per host and a
// live MJPEG stream holds one for as long as it runs: the program monitor alone streams, the others
// are single pictures.
import { send, sessionPath } from "./api.js";
import { withNames } from "./names.js";
import { state } from "./state.js";

export const MONITOR_WIDTH_PX = 320;   // the pictures' width (the server's default); the height follows the lens
const PROGRAM_FPS = 4;                 // the program monitor's live stream, pictures a second

export function watch(sessionId) {   // the monitors of a newly selected session: its live stream, the others emptied
  const program = document.getElementById("program-view");
  // Set only here, never on a poll: each new src would open another stream.
  program.src = `${sessionPath(sessionId)}/view.mjpeg?fps=${PROGRAM_FPS}&width=${MONITOR_WIDTH_PX}`;
  document.getElementById("program-view-status").textContent = "";
  state.cutShown = null;
  showCutPictures([]);
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
           placeholder: reply.headers.get("X-Camdirector-Placeholder"),
           labels: JSON.parse(reply.headers.get("X-Camdirector-Labels") || "[]") };   // the names drawn over players
}

const FIRST_SHOT_ID = 1;   // shot ids count a session's cuts, its first pose the first (pipeline/session.py)

// The last cut's before and after, asked for when a newer cut appears in the frames (and once per
// session, for a cut older than the frames kept). Fetched rather than set as src: the headers say
// which cut the server holds. The session's first pose is a cut with nothing before it: the server
// holds no pictures of it, and the caption says what it is rather than "no cut yet".
export async function showLastCut(frames) {
  const sessionId = state.selected;
  const cuts = frames.filter((f) => f.cut && f.camera);
  const newest = cuts.length ? cuts[cuts.length - 1] : null;
  const key = `${sessionId} ${newest ? newest.frame : "none"}`;
  if (key === state.cutShown) return;
  state.cutShown = key;
  if (newest && newest.shot_id === FIRST_SHOT_ID) {
    showCutPictures([]);
    document.getElementById("cut-caption").textContent =
      `Frame ${newest.frame} began the first shot: the session's first pose, with no frame before it to cut from.`;
    return;
  }
  // The cut's frame in the address: a new picture per cut, never a cached one.
  const base = `${sessionPath(sessionId)}/view?width=${MONITOR_WIDTH_PX}&frame=${newest ? newest.frame : "none"}&shot=`;
  let before, after;
  try {
    [before, after] = await Promise.all([picture(base + "cut_before"), picture(base + "cut_after")]);
  } catch (error) {
    if (state.cutShown === key) state.cutShown = null;   // asked again on the next poll
    return;
  }
  // The server shares a picture made a moment ago, or still being made, with whoever asks for the
  // same view (front/view_hub.py): one asked for before this cut may answer. Another cut's pictures
  // (or "no cut yet") are not shown as this one's: asked again on the next poll.
  if (newest && after.frame !== String(newest.frame) && state.cutShown === key) state.cutShown = null;
  if (state.cutShown !== key) {   // that, or another session was picked, or a newer cut asked for, meanwhile
    URL.revokeObjectURL(before.url);
    URL.revokeObjectURL(after.url);
    return;
  }
  showCutPictures([before.url, after.url], after.labels);
  document.getElementById("cut-caption").textContent = cutCaption(before, after, frames);
}

// [before, after] as object URLs, or [] to empty both monitors; labels: the names the cut's own
// picture labels its players with (X-Camdirector-Labels), said under it.
function showCutPictures(urls, labels = []) {
  document.getElementById("cut-labels").textContent = labels.length ? `Labelled: ${labels.join(", ")}.` : "";
  state.cutPictures.forEach((url) => URL.revokeObjectURL(url));
  state.cutPictures = urls;
  ["cut-before", "cut-after"].forEach((id, k) => {
    const img = document.getElementById(id);
    if (urls.length) img.src = urls[k];
    else img.removeAttribute("src");
  });
}

function cutCaption(before, after, frames) {
  if (after.placeholder) return `Nothing to show: ${after.placeholder}.`;
  const cut = frames.find((f) => String(f.frame) === after.frame);
  const why = cut ? [cut.shot ? withNames(cut.shot.reason) : null, ...cut.flags].filter(Boolean) : [];
  return `Cut at frame ${after.frame} (from frame ${before.frame})` +
    (cut ? ` to shot ${cut.shot_id}: ${why.length ? why.join(", ") : "new shot"}.` : ".");
}
