// The selected session, polled: GET /v1/sessions/{id} with only the frames not seen yet, kept in
// the state's buffer, then shown by every panel of the session (its players' names, monitors, top
// view, timeline, why the camera moved, the match's program, the style and, in a map mode, the
// anticipation map).
import { api, sessionPath } from "./api.js";
import { showMatch } from "./match.js";
import { showLastCut } from "./monitors.js";
import { showRoster } from "./names.js";
import { state } from "./state.js";
import { showStyle } from "./style.js";
import { drawTimeline } from "./timeline.js";
import { drawTopView, loadTopView } from "./topview.js";
import { showWhy } from "./why.js";

const TIMELINE_FRAMES = 600;     // frames shown, as many as the server keeps per session
const EVENT_LOG_SIZE = 50;       // game events listed for a MATCH session, newest first
const MAP_MODES = ["ANTICIPATION", "NO_ANTICIPATION"];   // the styles that build the map

export async function refreshSession() {
  const sessionId = state.selected;
  if (!sessionId) return;
  if (state.buffered.session !== sessionId) state.buffered = { session: sessionId, frames: [], events: [] };
  const newest = state.buffered.frames[state.buffered.frames.length - 1];
  // A MATCH session's program frames replace its buffering ones and are numbered from the game's
  // first moment: while buffering, ask for everything.
  const seen = newest && !newest.buffering ? newest.frame : null;
  let detail;
  try {   // only the frames not seen yet: a few dozen a poll instead of 600
    detail = await api(sessionPath(sessionId) + (seen === null ? "" : `?after_frame=${seen}`));
  } catch (error) {
    return;  // closed or reclaimed: the list says so
  }
  const buffered = state.buffered;
  if (buffered.session !== sessionId) return;   // another session was picked meanwhile
  // Asks overlap (a slow answer outlasts the poll's period; a click or a style applied asks at
  // once): an answer asked for before another one was added holds frames the buffer has now, and
  // added too would count and list their cuts and events once per answer. The next poll asks anew.
  if (buffered.frames[buffered.frames.length - 1] !== newest) return;
  const fresh = detail.frames.flatMap((f) => f.events || []);
  if (seen === null) {
    buffered.frames = detail.frames;
    buffered.events = fresh;
  } else {
    buffered.frames = buffered.frames.concat(detail.frames).slice(-TIMELINE_FRAMES);
    buffered.events = buffered.events.concat(fresh).slice(-EVENT_LOG_SIZE);
  }
  const frames = buffered.frames;
  showRoster(detail.roster);   // first: every panel after it names the players
  loadTopView(sessionId);
  showLastCut(frames);
  drawTopView(frames);
  drawTimeline(frames);
  showWhy(frames);
  showMatch(frames, buffered.events);
  showStyle(detail.style);
  showAnticipationMap(detail.style, frames);
}

function showAnticipationMap(style, frames) {
  const mapMode = MAP_MODES.includes(style.visibility) && frames.length > 0;
  document.getElementById("amap-figure").hidden = !mapMode;
  if (mapMode) {   // the frame number makes each poll fetch the map anew
    document.getElementById("amap").src = `${sessionPath(state.selected)}/amap.png` +
      `?frame=${frames[frames.length - 1].frame}`;
  }
}
