// The top view (x right, z down): the world seen from straight above, fetched once per session from
// /v1/sessions/{id}/topview.png (the server draws it once), then drawn under the trails on every
// poll: the camera's, the targets' (the players' in their team's colour in a match), the cuts and
// where the framing was lost.
import { send, sessionPath } from "./api.js";
import { FRAMING_COLOUR, FRAMING_LOST } from "./framing.js";
import { state } from "./state.js";

const TOP_VIEW_MARGIN_M = 2.0;   // space around the trails in the top view, m
const TOP_VIEW_RETRY_MS = 5000;  // a top view picture that failed (a busy renderer) is asked again after this
const TEAM_COLOURS = ["#e07b00", "#8e24aa", "#2e7d32", "#795548"];   // by team number, cycling

export async function loadTopView(sessionId) {
  const kept = state.topViews[sessionId];
  if (kept && !(kept.failedMs && Date.now() - kept.failedMs >= TOP_VIEW_RETRY_MS)) return;
  state.topViews[sessionId] = { pending: true };
  try {
    const reply = await send(`${sessionPath(sessionId)}/topview.png`);
    const bounds = reply.headers.get("X-Camdirector-Bounds-M");
    if (!bounds) {   // no static geometry: the picture is a card saying so, nothing to draw under the trails
      state.topViews[sessionId] = { image: null, world: null };
      return;
    }
    const [x0, z0, x1, z1] = bounds.split(",").map(Number);
    state.topViews[sessionId] = { image: await createImageBitmap(await reply.blob()), world: { x0, z0, x1, z1 } };
  } catch (error) {
    state.topViews[sessionId] = { failedMs: Date.now() };
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

export function drawTopView(frames) {
  const canvas = document.getElementById("topview");
  const g = canvas.getContext("2d");
  g.clearRect(0, 0, canvas.width, canvas.height);
  if (!frames.length) return;
  const { image, world } = state.topViews[state.selected] || {};
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

