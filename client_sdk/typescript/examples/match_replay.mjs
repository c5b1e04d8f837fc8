// Replays a match into a RIG_MATCH session and prints each shot and candidate as it changes.
//
//   node examples/match_replay.mjs grpc://127.0.0.1:50051 [match.jsonl]
//
// match.jsonl: one JSON object per game frame, {"timeS": 0.033, "players": [{"id": "a0", "team": 0,
// "p": [x, y, z], "q": [x, y, z, w]}, ...], "events": [{"kind": 1, "actorId": "a0", "otherActorId":
// "b0"}]} in our frame (metres, +Y up; convert with fromUnityPosition / fromUnrealPosition first).
// Without a file, four players circle two duels for 20 s and a0 kills b0 at 8 s.
// The key: CAMDIRECTOR_KEY; TLS: a grpcs:// URL and CAMDIRECTOR_CA (a PEM file).
import { readFileSync } from "node:fs";
import { connect, pb } from "../dist/index.js";

const [url = "grpc://127.0.0.1:50051", file] = process.argv.slice(2);

function* synthetic() {
  const ids = ["a0", "a1", "b0", "b1"];
  for (let k = 0; k < 600; k++) {
    const t = k / 30;
    yield {
      timeS: t,
      players: ids.map((id, i) => {
        const cx = i % 2 === 0 ? 0 : 8, angle = 0.4 * t + (id.startsWith("b") ? Math.PI : 0);
        const x = cx + 2.5 * Math.cos(angle), z = 2.5 * Math.sin(angle), yaw = Math.atan2(cx - x, -z);
        return { id, team: id.startsWith("a") ? 0 : 1, p: [x, 0.9, z], q: [0, Math.sin(yaw / 2), 0, Math.cos(yaw / 2)] };
      }),
      events: k === 240 ? [{ kind: pb.EventKind.EVENT_KILL, actorId: "a0", otherActorId: "b0" }] : [],
    };
  }
}

const frames = file ? readFileSync(file, "utf8").split("\n").filter(Boolean).map((line) => JSON.parse(line)) : [...synthetic()];
const capsule = { source: { case: "primitive", value: { shape: { case: "capsule", value: { radius: 0.3, height: 1.8 } } } } };
const client = connect(url, { caFile: process.env.CAMDIRECTOR_CA });
const session = await client.createSession({
  targets: frames[0].players.map((pl) => ({
    id: pl.id, team: pl.team, mesh: capsule, aimOffset: { y: 0.6 },
    transform: { position: { x: pl.p[0], y: pl.p[1], z: pl.p[2] } },
  })),
  style: { rig: pb.Rig.MATCH },
});

async function* updates() {
  for (const [k, f] of frames.entries()) {
    yield {
      frame: BigInt(k + 1), timeS: f.timeS, events: f.events ?? [],
      states: f.players.map((pl) => ({ id: pl.id, transform: {
        position: { x: pl.p[0], y: pl.p[1], z: pl.p[2] }, rotation: { x: pl.q[0], y: pl.q[1], z: pl.q[2], w: pl.q[3] } } })),
    };
  }
}

const describe = (shot) => `${pb.ShotKind[shot?.kind ?? 0]} ${(shot?.subjectIds ?? []).join("+") || "-"}`;
let lastShot = "", lastCandidates = "";
for await (const u of session.stream(updates())) {
  const shot = `${describe(u.shot)}${u.shot?.held ? " (held)" : ""}: ${u.shot?.reason ?? ""}`;
  if (shot !== lastShot) console.log(`t=${u.timeS.toFixed(2)} s  shot ${shot}${u.cut ? "  [cut]" : ""}`);
  const candidates = u.candidates.map((c) => `${describe(c.shot)} ${c.score.toFixed(2)}`).join(", ");
  if (candidates.replace(/ \d\.\d\d/g, "") !== lastCandidates.replace(/ \d\.\d\d/g, "")) {
    console.log(`t=${u.timeS.toFixed(2)} s  candidates ${candidates || "-"}`);
  }
  lastShot = shot; lastCandidates = candidates;
}
console.log(`frames answered: ${await session.close()}`);
client.close();
