// The timeline strip of the frames kept: one shade per shot with the cuts in red, the visibility,
// and the framing error with the line above which the framing is lost; and the summary under it.
import { FRAMING_COLOUR, FRAMING_LOST, FRAMING_STRIP_MAX } from "./framing.js";

export function drawTimeline(frames) {
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
