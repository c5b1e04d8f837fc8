// The director's dashboard. Reads the REST API only: /healthz, /v1/sessions, /v1/sessions/{id},
// PUT /v1/sessions/{id}/style, POST /v1/sessions/{id}/take (a MATCH session's take and release),
// the monitors' /v1/sessions/{id}/view, view.mjpeg and topview.png, /v1/overview-jobs; and who
// the caller is, /v1/whoami, /v1/login and /v1/logout (docs/security.md). Data is written with
// textContent, never as HTML.
//
// With authentication on, the page is shown a key once, in the login form: /v1/login answers with
// the login cookie (HttpOnly: no script here reads it), and the key itself is kept nowhere, not in
// storage, the address or the form. Every request then goes with the cookie; one that changes
// anything carries the CSRF token the login gave. Without authentication (`--no-auth`) /v1/whoami
// answers at once and no form is shown.
"use strict";

const POLL_SESSIONS_MS = 1000;   // the session list and the jobs
const POLL_SESSION_MS = 500;     // the selected session's frames
const TOP_VIEW_MARGIN_M = 2.0;   // space around the trails in the top view, m
const TOP_VIEW_RETRY_MS = 5000;  // a top view picture that failed (a busy renderer) is asked again after this

// The monitors. A browser keeps about six connections per host and a live MJPEG stream holds one
// for as long as it runs: the program monitor alone streams, the others are single pictures.
const MONITOR_WIDTH_PX = 320;    // the pictures' width (the server's default); the height follows the lens
const PROGRAM_FPS = 4;           // the program monitor's live stream, pictures a second
const CANDIDATE_REFRESH_MS = 1000;   // candidate pictures: about once a second, not on every poll

const MAP_MODES = ["ANTICIPATION", "NO_ANTICIPATION"];   // the styles that build the map
const RIG_FIELDS = { RIG_TORIC: "toric-fields", RIG_TRACKS: "tracks-fields", RIG_MATCH: "match-fields" };
const MATCH_NUMBERS = ["minShotS", "maxShotS"];          // a match's style numbers the form edits

const TIMELINE_FRAMES = 600;     // frames shown, as many as the server keeps per session
const EVENT_LOG_SIZE = 50;       // game events listed for a MATCH session, newest first
const TEAM_COLOURS = ["#e07b00", "#8e24aa", "#2e7d32", "#795548"];   // by team number, cycling

// The framing error (docs/protocol.md): how far the framed points land from where the style puts
// them, normalised screen units (the frame is [-1, 1]; null where the rig does not measure it).
// Above FRAMING_LOST the framing has failed: a point is a quarter of the frame's height from its
// place. That puts a long or medium tracks shot's framed ends (placed at y -0.8 and 0.8) 0.3 out
// of the frame, and a Toric target (at x -1/3 or 1/3 by default) drifting outward at x 0.83, by
// the frame's side edge.
const FRAMING_LOST = 0.5;
const FRAMING_STRIP_MAX = 1.0;   // the strip's framing band spans 0 to a frame's half-height; above is clipped
const FRAMING_COLOUR = "#e040fb";   // its line in the strip and the top view's marks: no other mark's colour

let selected = null;             // the selected session id
let styleSentBySession = {};     // session id -> the style the form was last filled from (JSON text)
let currentStyle = {};           // the selected session's style, as the server reported it
let buffered = { session: null, frames: [], events: [] };   // the selected session's frames and game events seen
let candidatesShown = "";        // the candidate shots the table shows (JSON), rebuilt only when they change
let candidatesPictured = { frame: null, ms: 0 };   // the frame the candidate monitors last asked for, and when
let cutShown = null;             // the cut the before/after monitors show: "<session> <newest cut frame seen>"
let cutPictures = [];            // their object URLs, released when replaced
let topViews = {};               // session id -> its top view: { image, world } once fetched, { failedMs } after a failure

// The caller, as /v1/whoami or /v1/login describe it: { key_id, role, tenant, csrf_token }
// (key_id and csrf_token null without authentication); null while nobody is logged in.
let caller = null;

// The verbs the dashboard's controls use and what each control does. Whether the caller's key
// has a verb comes from /v1/whoami (its role's verbs, access/roles.py); only to switch a control
// off beforehand and say why: the server decides, and a refusal shows where the control's result does.
const CONTROLS = {
  "session.take": "take and release shots",
  "session.style": "change a session's style",
  "job.submit": "submit overview jobs",
};
const SAFE_METHODS = ["GET", "HEAD", "OPTIONS"];   // the methods the server asks no CSRF token of (front/http/auth.py)

class ApiError extends Error {   // the server answered, not with 2xx: its status, and its own words in detail
  constructor(status, detail) {
    super(`${status}: ${detail}`);
    this.status = status;
    this.detail = detail;
  }
}

// Every request of the page. The login cookie goes with it (same origin); a request that changes
// anything carries the CSRF token; a 401 (the key revoked, the login expired) brings the login form
// back with the server's reason.
async function send(path, options = {}) {
  const headers = new Headers(options.headers);
  if (!SAFE_METHODS.includes((options.method || "GET").toUpperCase()) && caller && caller.csrf_token) {
    headers.set("X-CSRF-Token", caller.csrf_token);
  }
  const reply = await fetch(path, { ...options, headers, credentials: "same-origin" });
  if (reply.ok) return reply;
  const text = await reply.text();
  const body = text ? JSON.parse(text) : {};
  const detail = Array.isArray(body.detail)
    ? body.detail.map((d) => `${(d.loc || []).join(".")}: ${d.msg}`).join("; ")
    : body.detail || reply.statusText;
  if (reply.status === 401) showLogin(detail);
  throw new ApiError(reply.status, detail);
}

async function api(path, options = {}) {
  const text = await (await send(path, options)).text();
  return text ? JSON.parse(text) : {};
}

function cell(row, text) {
  const td = document.createElement("td");
  td.textContent = text;
  row.appendChild(td);
  return td;
}

// -- sessions -------------------------------------------------------------------------------

async function refreshSessions() {
  const health = await api("/healthz");
  const who = caller;
  const { sessions } = await api("/v1/sessions");
  if (caller !== who) return;   // logged out meanwhile: the list was the last key's
  // The tenant's sessions (the list's), not /healthz's count of the whole node's.
  document.getElementById("health").textContent =
    `${health.status}: ${sessions.length} sessions of tenant ${caller.tenant}, ${health.workers} workers`;
  const body = document.querySelector("#sessions tbody");
  body.replaceChildren();
  for (const s of sessions) {
    const row = document.createElement("tr");
    row.dataset.session = s.session_id;
    row.classList.toggle("selected", s.session_id === selected);
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
  for (const id of Object.keys(topViews)) {   // an ended session's top view is not needed again
    if (!sessions.some((s) => s.session_id === id)) delete topViews[id];
  }
  if (selected && !sessions.some((s) => s.session_id === selected)) {
    document.getElementById("shot-summary").textContent = "the session has ended";
  }
}

function select(sessionId) {
  const changed = sessionId !== selected;
  selected = sessionId;
  document.getElementById("session-panel").hidden = false;
  document.getElementById("session-id").textContent = sessionId;
  document.getElementById("style-result").textContent = "";
  for (const row of document.querySelectorAll("#sessions tbody tr")) {
    row.classList.toggle("selected", row.dataset.session === sessionId);
  }
  if (changed) watch(sessionId);
  refreshSession();
}

// -- monitors -------------------------------------------------------------------------------

function sessionPath(sessionId) {
  return `/v1/sessions/${encodeURIComponent(sessionId)}`;
}

function watch(sessionId) {   // the monitors of a newly selected session: its live stream, the others emptied
  const program = document.getElementById("program-view");
  // Set only here, never on a poll: each new src would open another stream.
  program.src = `${sessionPath(sessionId)}/view.mjpeg?fps=${PROGRAM_FPS}&width=${MONITOR_WIDTH_PX}`;
  document.getElementById("program-view-status").textContent = "";
  cutShown = null;
  for (const id of ["cut-before", "cut-after"]) document.getElementById(id).removeAttribute("src");
  document.getElementById("cut-caption").textContent = "No cut yet.";
  candidatesShown = "";
  candidatesPictured = { frame: null, ms: 0 };
  document.querySelector("#candidates tbody").replaceChildren();
}

function programStopped() {   // the stream ended (the session did) or was refused (too many streams)
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
async function showLastCut(frames) {
  const sessionId = selected;
  const cuts = frames.filter((f) => f.cut && f.camera);
  const newest = cuts.length ? cuts[cuts.length - 1].frame : "none";
  const key = `${sessionId} ${newest}`;
  if (key === cutShown) return;
  cutShown = key;
  // The cut's frame in the address: a new picture per cut, never a cached one.
  const base = `${sessionPath(sessionId)}/view?width=${MONITOR_WIDTH_PX}&frame=${newest}&shot=`;
  let before, after;
  try {
    [before, after] = await Promise.all([picture(base + "cut_before"), picture(base + "cut_after")]);
  } catch (error) {
    if (cutShown === key) cutShown = null;   // asked again on the next poll
    return;
  }
  if (cutShown !== key) {   // another session was picked, or a newer cut asked for, meanwhile
    URL.revokeObjectURL(before.url);
    URL.revokeObjectURL(after.url);
    return;
  }
  cutPictures.forEach((url) => URL.revokeObjectURL(url));
  cutPictures = [before.url, after.url];
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

// The top view's world: fetched once per session (the server draws it once), then drawn under
// the trails on every poll.
async function loadTopView(sessionId) {
  const kept = topViews[sessionId];
  if (kept && !(kept.failedMs && Date.now() - kept.failedMs >= TOP_VIEW_RETRY_MS)) return;
  topViews[sessionId] = { pending: true };
  try {
    const reply = await send(`${sessionPath(sessionId)}/topview.png`);
    const bounds = reply.headers.get("X-Camdirector-Bounds-M");
    if (!bounds) {   // no static geometry: the picture is a card saying so, nothing to draw under the trails
      topViews[sessionId] = { image: null, world: null };
      return;
    }
    const [x0, z0, x1, z1] = bounds.split(",").map(Number);
    topViews[sessionId] = { image: await createImageBitmap(await reply.blob()), world: { x0, z0, x1, z1 } };
  } catch (error) {
    topViews[sessionId] = { failedMs: Date.now() };
  }
}

async function refreshSession() {
  const sessionId = selected;
  if (!sessionId) return;
  if (buffered.session !== sessionId) buffered = { session: sessionId, frames: [], events: [] };
  const newest = buffered.frames[buffered.frames.length - 1];
  // A MATCH session's program frames replace its buffering ones and are numbered from the game's
  // first moment: while buffering, ask for everything.
  const seen = newest && !newest.buffering ? newest.frame : null;
  let detail;
  try {   // only the frames not seen yet: a few dozen a poll instead of 600
    detail = await api(`/v1/sessions/${encodeURIComponent(sessionId)}` + (seen === null ? "" : `?after_frame=${seen}`));
  } catch (error) {
    return;  // closed or reclaimed: the list says so
  }
  if (buffered.session !== sessionId) return;   // another session was picked meanwhile
  const fresh = detail.frames.flatMap((f) => f.events || []);
  if (seen === null) {
    buffered.frames = detail.frames;
    buffered.events = fresh;
  } else {
    buffered.frames = buffered.frames.concat(detail.frames).slice(-TIMELINE_FRAMES);
    buffered.events = buffered.events.concat(fresh).slice(-EVENT_LOG_SIZE);
  }
  const frames = buffered.frames;
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
    document.getElementById("amap").src = `/v1/sessions/${encodeURIComponent(selected)}/amap.png` +
      `?frame=${frames[frames.length - 1].frame}`;
  }
}

function bounds(frames, world) {   // the trails' with a margin, and all of the world's picture (its own margin in it)
  const xs = [], zs = [];
  const add = (p) => { xs.push(p[0]); zs.push(p[2]); };
  for (const f of frames) {
    if (f.camera) add(f.camera);   // none while a MATCH session buffers
    f.targets.forEach(add);
  }
  for (const c of frames[frames.length - 1].candidates || []) add(c.camera);
  const b = { x0: Math.min(...xs) - TOP_VIEW_MARGIN_M, x1: Math.max(...xs) + TOP_VIEW_MARGIN_M,
              z0: Math.min(...zs) - TOP_VIEW_MARGIN_M, z1: Math.max(...zs) + TOP_VIEW_MARGIN_M };
  if (!world) return b;
  return { x0: Math.min(b.x0, world.x0), x1: Math.max(b.x1, world.x1),
           z0: Math.min(b.z0, world.z0), z1: Math.max(b.z1, world.z1) };
}

function drawTopView(frames) {
  const canvas = document.getElementById("topview");
  const g = canvas.getContext("2d");
  g.clearRect(0, 0, canvas.width, canvas.height);
  if (!frames.length) return;
  const { image, world } = topViews[selected] || {};
  const b = bounds(frames, world);
  const scale = Math.min(canvas.width / (b.x1 - b.x0), canvas.height / (b.z1 - b.z0));
  const at = (p) => [(p[0] - b.x0) * scale, (p[2] - b.z0) * scale];
  // The mapping drawn with, for tests and tools: canvas px = (world m - x0 or z0) * scale.
  canvas.dataset.bounds = JSON.stringify({ ...b, scale, world: world || null });
  if (world) {   // the picture spans its world rectangle exactly, x right and z down as here
    g.drawImage(image, ...at([world.x0, 0, world.z0]), (world.x1 - world.x0) * scale, (world.z1 - world.z0) * scale);
  }
  const trail = (points, colour) => {
    g.strokeStyle = colour;
    g.beginPath();
    points.forEach((p, i) => (i ? g.lineTo(...at(p)) : g.moveTo(...at(p))));
    g.stroke();
  };
  const last = frames[frames.length - 1];
  const colour = (k) => (last.teams ? TEAM_COLOURS[last.teams[k] % TEAM_COLOURS.length] : "#e07b00");
  for (let k = 0; k < last.targets.length; k++) {
    trail(frames.filter((f) => f.targets.length > k).map((f) => f.targets[k]), colour(k));
  }
  last.targets.forEach((t, k) => {               // where each target is now
    g.fillStyle = colour(k);
    g.beginPath();
    g.arc(...at(t), 4, 0, 2 * Math.PI);
    g.fill();
  });
  if (last.players) drawMatchMarks(g, at, last);
  const posed = frames.filter((f) => f.camera);
  if (!posed.length) return;
  trail(posed.map((f) => f.camera), "#2a62c9");
  g.strokeStyle = "#c62828";
  for (const f of frames.filter((f) => f.cut)) {
    g.beginPath();
    g.arc(...at(f.camera), 6, 0, 2 * Math.PI);
    g.stroke();
  }
  g.strokeStyle = FRAMING_COLOUR;   // where along the trail the framing was lost: a cross on the camera
  g.lineWidth = 2;
  for (const f of posed.filter((f) => f.framing_error > FRAMING_LOST)) {
    const [x, z] = at(f.camera);
    g.beginPath();
    g.moveTo(x - 4, z - 4);
    g.lineTo(x + 4, z + 4);
    g.moveTo(x - 4, z + 4);
    g.lineTo(x + 4, z - 4);
    g.stroke();
  }
  g.lineWidth = 1;
  const camera = posed[posed.length - 1];
  const [cx, cz] = at(camera.camera);
  g.strokeStyle = "#2a62c9";
  g.lineWidth = 2;
  g.beginPath();
  g.moveTo(cx, cz);
  g.lineTo(cx + camera.forward[0] * 30, cz + camera.forward[2] * 30);
  g.stroke();
  g.lineWidth = 1;
}

function drawMatchMarks(g, at, last) {   // the program's subjects ringed, the candidates' cameras
  g.strokeStyle = "#222";
  for (const id of last.shot ? last.shot.subject_ids : []) {
    const k = last.players.indexOf(id);
    g.beginPath();
    g.arc(...at(last.targets[k]), 8, 0, 2 * Math.PI);
    g.stroke();
  }
  g.strokeStyle = g.fillStyle = "#888";
  for (const c of last.candidates) {
    const [x, z] = at(c.camera);
    g.fillRect(x - 3, z - 3, 6, 6);
    g.beginPath();
    g.moveTo(x, z);
    g.lineTo(x + c.forward[0] * 15, z + c.forward[2] * 15);
    g.stroke();
  }
}

function drawTimeline(frames) {
  const canvas = document.getElementById("timeline");
  const g = canvas.getContext("2d");
  g.clearRect(0, 0, canvas.width, canvas.height);
  if (!frames.length) return;
  const w = canvas.width / frames.length, shotBand = 40, visTop = 55, visHeight = 60, errTop = 125, errHeight = 40;
  frames.forEach((f, i) => {
    g.fillStyle = f.shot_id % 2 ? "#9bb9e8" : "#c9d9f2";   // alternate shades, one per shot
    g.fillRect(i * w, 0, Math.ceil(w), shotBand);
    if (f.cut) {
      g.fillStyle = "#c62828";
      g.fillRect(i * w, 0, Math.max(2, w), shotBand);
    }
  });
  g.strokeStyle = "#1b7f3b";
  g.beginPath();
  frames.forEach((f, i) => {
    const y = visTop + (1 - f.visibility) * visHeight;
    i ? g.lineTo(i * w, y) : g.moveTo(0, y);
  });
  g.stroke();
  drawFramingBand(g, frames, w, errTop, errHeight);
  const shots = new Set(frames.map((f) => f.shot_id));
  const cuts = frames.filter((f) => f.cut).length;
  const visible = frames.reduce((s, f) => s + f.visibility, 0) / frames.length;
  document.getElementById("shot-summary").textContent =
    `frames ${frames[0].frame}–${frames[frames.length - 1].frame}: ${shots.size} shots, ` +
    `${cuts} cuts, mean visibility ${visible.toFixed(2)}, shot ${frames[frames.length - 1].shot_id} now` +
    framingSummary(frames);
}

function drawFramingBand(g, frames, w, top, height) {   // the framing error, 0 at the band's bottom
  const y = (error) => top + height * (1 - Math.min(error, FRAMING_STRIP_MAX) / FRAMING_STRIP_MAX);
  g.strokeStyle = "#bbb";
  g.setLineDash([4, 4]);
  g.beginPath();
  g.moveTo(0, y(FRAMING_LOST));
  g.lineTo(g.canvas.width, y(FRAMING_LOST));
  g.stroke();
  g.setLineDash([]);
  g.strokeStyle = FRAMING_COLOUR;
  g.beginPath();
  let drawing = false;   // a frame with no framing error breaks the line
  frames.forEach((f, i) => {
    if (f.framing_error === null) {
      drawing = false;
      return;
    }
    drawing ? g.lineTo(i * w, y(f.framing_error)) : g.moveTo(i * w, y(f.framing_error));
    drawing = true;
  });
  g.stroke();
}

function framingSummary(frames) {   // the newest framing error, the largest shown and the frames it was lost in
  const measured = frames.filter((f) => f.framing_error !== null);
  if (!measured.length) return "";   // a rig that does not measure it
  const newest = frames[frames.length - 1].framing_error;
  const most = Math.max(...measured.map((f) => f.framing_error));
  const lost = measured.filter((f) => f.framing_error > FRAMING_LOST).length;
  return `; framing error ${newest === null ? "not measured" : newest.toFixed(2)} now, ` +
    `at most ${most.toFixed(2)}, lost (above ${FRAMING_LOST}) in ${lost} frames`;
}

function showWhy(frames) {
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
    const why = [f.shot ? f.shot.reason : null, ...f.flags].filter(Boolean);
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

// -- match ----------------------------------------------------------------------------------

function describeShot(shot) {
  const who = shot.subject_ids.length ? shot.subject_ids.join(", ") : "the map";
  return `${shot.kind.replace("SHOT_", "")} ${who}`;
}

function showMatch(frames, events) {
  const last = frames[frames.length - 1];
  const match = Boolean(last && last.players);
  document.getElementById("match-view").hidden = !match;
  document.getElementById("match-caption").hidden = !match;
  if (!match) return;
  const program = document.getElementById("program-shot");
  // The match rig starts the reason of a human's shot, and of its fallback, with "take".
  const held = Boolean(last.shot && last.shot.held);
  program.textContent = last.buffering || !last.shot ? "buffering: the broadcast delay is filling, no camera yet"
    : `${describeShot(last.shot)} (${held ? "held" : "the director's"}): ${last.shot.reason}`;
  program.classList.toggle("held", held);
  document.getElementById("release").hidden = !held;
  const cut = last.planned_cut;
  document.getElementById("planned-cut").textContent = cut
    ? `in ${(cut.time_s - last.time_s).toFixed(1)} s (at ${cut.time_s.toFixed(1)} s) to ${describeShot(cut.shot)}: ` +
      cut.shot.reason
    : held ? "none while a take is held" : "none: the director decides as the game goes (a delay shows what it plans)";
  showCandidates(last.candidates, last.frame);
  const log = document.getElementById("event-log");
  log.replaceChildren(...events.slice().reverse().map((e) => {
    const li = document.createElement("li");
    const who = e.other_actor_id ? `${e.actor_id} → ${e.other_actor_id}` : e.actor_id;
    li.textContent = `${e.time_s.toFixed(2)} s ${e.kind.replace("EVENT_", "").toLowerCase()} ${who}` +
      (e.label ? `: ${e.label}` : "");
    return li;
  }));
}

// One monitor per candidate shot, its take button under it. The rows are rebuilt only when the
// shots offered change, so that a button does not move under the pointer between polls; their
// reasons and interest are rewritten in place, and their pictures asked anew about once a second.
function showCandidates(candidates, frame) {
  const body = document.querySelector("#candidates tbody");
  const key = JSON.stringify(candidates.map((c) => [c.shot.kind, c.shot.subject_ids]));
  if (key !== candidatesShown) {
    candidatesShown = key;
    const kept = new Map([...body.rows].map((row) => [row.dataset.key, row]));   // their pictures stay
    body.replaceChildren(...candidates.map((c) => kept.get(candidateKey(c)) || candidateRow(c)));
    candidatesPictured = { frame: null, ms: 0 };   // a new monitor gets its picture now
  }
  candidates.forEach((c, i) => {
    const row = body.rows[i];
    row.querySelector(".candidate-why").textContent = c.shot.reason;
    row.querySelector(".candidate-interest").textContent = `interest ${c.score.toFixed(2)}`;
  });
  const now = Date.now();
  if (frame === candidatesPictured.frame || now - candidatesPictured.ms < CANDIDATE_REFRESH_MS) return;
  candidatesPictured = { frame, ms: now };
  for (const img of body.querySelectorAll("img")) {   // the frame in the address: a new picture, not the cached one
    img.src = `${sessionPath(selected)}/view?shot=candidate&subjects=${encodeURIComponent(img.dataset.subjects)}` +
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
  img.alt = `what the candidate shot of ${c.shot.subject_ids.join(", ")} would show`;
  img.dataset.testid = "candidate-view";
  img.dataset.subjects = row.dataset.subjects;
  const monitor = cell(row, "");
  monitor.className = "candidate-monitor";
  monitor.appendChild(img);
  cell(row, c.shot.kind.replace("SHOT_", "")).className = "candidate-kind";
  cell(row, c.shot.subject_ids.join(", "));
  cell(row, "").className = "candidate-why";
  cell(row, "").className = "candidate-interest";
  const button = document.createElement("button");
  button.textContent = "take";
  gate(button, "session.take");
  button.addEventListener("click", () => take({ subject_ids: c.shot.subject_ids, kind: c.shot.kind }));
  cell(row, "").appendChild(button);
  return row;
}

async function take(body) {
  const result = document.getElementById("take-result");
  try {
    const reply = await api(`/v1/sessions/${encodeURIComponent(selected)}/take`, {
      method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body),
    });
    result.className = "ok";
    result.textContent = reply.shot ? `taken: ${describeShot(reply.shot)}, held until released` : "released";
  } catch (error) {
    result.className = "error";
    result.textContent = error.message;
  }
}

// -- style ----------------------------------------------------------------------------------

function showStyle(style) {
  currentStyle = style;
  const text = JSON.stringify(style, null, 1);
  document.getElementById("style-json").textContent = text;
  if (styleSentBySession[selected] === text) return;   // do not overwrite what the user is editing
  styleSentBySession[selected] = text;
  const form = document.getElementById("style-form");
  // Each rig's own fields: the others would be refused (or, for the Toric fields on a match, mean nothing).
  const rig = RIG_FIELDS[style.rig] ? style.rig : "RIG_TORIC";
  for (const [key, fieldset] of Object.entries(RIG_FIELDS)) {
    document.getElementById(fieldset).hidden = document.getElementById(fieldset).disabled = key !== rig;
  }
  form.visibility.value = style.visibility && style.visibility !== "VISIBILITY_MODE_UNSPECIFIED"
    ? style.visibility : "FRAMING_ONLY";
  for (const name of ["preferredPhiDeg", "preferredThetaRatio", "responseTimeS", "maxSpeedMS"]) {
    form[name].value = style[name] ?? "";
  }
  form.shotSize.value = style.shotSize || "SHOT_SIZE_LONG";
  form.movement.value = style.movement || "MOVEMENT_DYNAMIC_WITH_CUTS";
  form.matchDirector.value = style.matchDirector && style.matchDirector !== "MATCH_DIRECTOR_UNSPECIFIED"
    ? style.matchDirector : "MATCH_DIRECTOR_PLANNED";
  for (const name of MATCH_NUMBERS) form[name].value = style[name] ?? "";
}

async function applyStyle(event) {
  event.preventDefault();
  const form = event.target;
  const style = { ...currentStyle };   // PUT replaces the whole style: start from the session's
  if (style.rig === "RIG_TRACKS") {
    style.shotSize = form.shotSize.value;
    style.movement = form.movement.value;
  } else if (style.rig === "RIG_MATCH") {
    style.matchDirector = form.matchDirector.value;
    for (const name of MATCH_NUMBERS) {
      if (form[name].value === "") delete style[name];
      else style[name] = Number(form[name].value);
    }
  } else {
    style.visibility = form.visibility.value;
    for (const name of ["preferredPhiDeg", "preferredThetaRatio", "responseTimeS", "maxSpeedMS"]) {
      if (form[name].value === "") delete style[name];
      else style[name] = Number(form[name].value);
    }
  }
  const result = document.getElementById("style-result");
  try {
    await api(`/v1/sessions/${encodeURIComponent(selected)}/style`, {
      method: "PUT", headers: { "Content-Type": "application/json" }, body: JSON.stringify(style),
    });
    result.className = "ok";
    result.textContent = "applied";
    delete styleSentBySession[selected];
    refreshSession();
  } catch (error) {
    result.className = "error";
    result.textContent = error.message;
  }
}

// -- overview jobs --------------------------------------------------------------------------

async function refreshJobs() {
  const who = caller;
  const { jobs } = await api("/v1/overview-jobs?limit=50");
  if (caller !== who) return;   // logged out meanwhile: the list was the last key's
  const body = document.querySelector("#jobs tbody");
  body.replaceChildren();
  for (const j of jobs) {
    const row = document.createElement("tr");
    row.dataset.job = j.id;
    cell(row, j.id.slice(0, 12));
    cell(row, j.file_name);
    cell(row, j.frames);
    cell(row, j.error ? `${j.status}: ${j.error}` : j.status).dataset.status = j.status;
    cell(row, `${Math.round(j.progress * 100)}%`);
    const result = cell(row, "");
    if (j.status === "succeeded") {
      const view = document.createElement("button");
      view.textContent = "view";
      view.addEventListener("click", () => showJob(j.id));
      result.appendChild(view);
    }
    body.appendChild(row);
  }
}

function showJob(jobId) {
  document.getElementById("job-view").hidden = false;
  document.getElementById("job-video").src = `/v1/overview-jobs/${jobId}/preview.mp4`;
  document.getElementById("job-sheet").src = `/v1/overview-jobs/${jobId}/contact-sheet.png`;
}

async function submitOverview(event) {
  event.preventDefault();
  const result = document.getElementById("overview-result");
  try {
    const job = await api("/v1/overview-jobs", { method: "POST", body: new FormData(event.target) });
    result.className = "ok";
    result.textContent = `job ${job.id} ${job.status}`;
    refreshJobs();
  } catch (error) {
    result.className = "error";
    result.textContent = error.message;
  }
}

// -- who is logged in -----------------------------------------------------------------------

function may(verb) {
  return caller.verbs.includes(verb);
}

function gate(button, verb) {   // a control the caller's role may not use: off, saying why as the server would
  button.disabled = !may(verb);
  button.title = may(verb) ? "" : `a key of role '${caller.role}' may not ${verb} (docs/security.md)`;
}

function applyRole() {
  gate(document.getElementById("release"), "session.take");
  gate(document.querySelector('#style-form button[type="submit"]'), "session.style");
  gate(document.querySelector('#overview-form button[type="submit"]'), "job.submit");
  const refused = Object.keys(CONTROLS).filter((verb) => !may(verb));
  const note = document.getElementById("role-note");
  note.hidden = refused.length === 0;
  note.textContent = `A key of role '${caller.role}' may not ${refused.map((verb) => CONTROLS[verb]).join(", ")}: ` +
    "those buttons are off (docs/security.md).";
}

function loggedIn(who) {
  caller = who;
  document.getElementById("login-panel").hidden = true;
  document.getElementById("login-result").textContent = "";
  document.getElementById("dashboard").hidden = false;
  document.getElementById("who").textContent = who.key_id === null
    ? "authentication off: every caller is an admin of tenant default"
    : `${who.role} of tenant ${who.tenant} (key ${who.key_id})`;
  document.getElementById("logout").hidden = who.key_id === null;
  applyRole();
  polls.forEach((poll) => poll());
}

// What the page showed of the last key's sessions and jobs: the next key may be another tenant's.
function forget() {
  selected = null;
  styleSentBySession = {};
  buffered = { session: null, frames: [], events: [] };
  topViews = {};
  candidatesShown = "";
  document.getElementById("session-panel").hidden = true;
  document.getElementById("program-view").removeAttribute("src");   // ends its live stream
  document.getElementById("take-result").textContent = "";
  document.getElementById("job-view").hidden = true;
  for (const id of ["sessions", "candidates", "jobs"]) document.querySelector(`#${id} tbody`).replaceChildren();
}

function showLogin(message, className = "error") {
  caller = null;
  forget();
  document.getElementById("dashboard").hidden = true;
  document.getElementById("health").textContent = "not logged in";
  document.getElementById("who").textContent = "";
  document.getElementById("logout").hidden = true;
  document.getElementById("login-panel").hidden = false;
  const result = document.getElementById("login-result");
  result.className = className;
  result.textContent = message;
  document.querySelector('#login-form input[name="key"]').focus();
}

async function logIn(event) {
  event.preventDefault();
  const input = event.target.key;
  const key = input.value;
  input.value = "";   // the key is not kept, not even in the form: the cookie stands for it
  try {
    loggedIn(await api("/v1/login", {
      method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify({ key }),
    }));
  } catch (error) {
    showLogin(error instanceof ApiError ? error.detail : `unreachable: ${error.message}`);
  }
}

async function logOut() {
  try {
    await api("/v1/logout", { method: "POST" });
    showLogin("Logged out.", "ok");
  } catch (error) {
    showTrouble(error);
  }
}

async function identify() {   // who the login cookie makes the caller, or the open server's admin
  try {
    loggedIn(await api("/v1/whoami"));
  } catch (error) {
    showTrouble(error);
    if (!(error instanceof ApiError && error.status === 401)) setTimeout(identify, POLL_SESSIONS_MS);
  }
}

function showTrouble(error) {   // in the header: the server's refusal, or that it could not be reached
  if (error instanceof ApiError && error.status === 401) return;   // the login form says why
  document.getElementById("health").textContent =
    error instanceof ApiError ? error.message : `unreachable: ${error.message}`;
}

// -- start ----------------------------------------------------------------------------------

function every(ms, task) {   // a poll, run while someone is logged in; returned to be run at once after a login
  const run = () => {
    if (caller) task().catch(showTrouble);
  };
  setInterval(run, ms);
  return run;
}

for (const threshold of document.querySelectorAll(".framing-lost")) threshold.textContent = FRAMING_LOST;
document.getElementById("style-form").addEventListener("submit", applyStyle);
document.getElementById("release").addEventListener("click", () => take({ release: true }));
document.getElementById("overview-form").addEventListener("submit", submitOverview);
document.getElementById("program-view").addEventListener("error", programStopped);
document.getElementById("login-form").addEventListener("submit", logIn);
document.getElementById("logout").addEventListener("click", logOut);
const polls = [
  every(POLL_SESSIONS_MS, refreshSessions),
  every(POLL_SESSIONS_MS, refreshJobs),
  every(POLL_SESSION_MS, refreshSession),
];
identify();
