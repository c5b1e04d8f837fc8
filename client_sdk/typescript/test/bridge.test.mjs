// examples/game_state_bridge.mjs against a real server: posted game states (four players circling
// in two duels, a kill, the victim dead after it) answered with the program camera and shot, the
// same as a RIG_MATCH session fed the same frames directly through the SDK; bad states answered
// 400 or 404 with the reason; POST /reset closes the session.
import assert from "node:assert/strict";
import { spawn } from "node:child_process";
import { once } from "node:events";
import { createInterface } from "node:readline";
import { test } from "node:test";
import { connect, pb } from "../dist/index.js";
import { env } from "./helpers.mjs";

const URL_ = env("CAMDIRECTOR_TEST_URL");
const PLAYERS = ["a0", "a1", "b0", "b1"];
const KILL_AT = 40;

/** The feed's state k: players circling two centres, facing the middle; b0 killed at KILL_AT. */
function state(k) {
  const t = k / 30;
  return {
    time_s: t,
    players: PLAYERS.map((id, i) => {
      const cx = i % 2 === 0 ? 0 : 8, angle = 0.4 * t + (id.startsWith("b") ? Math.PI : 0);
      const x = cx + 2.5 * Math.cos(angle), z = 2.5 * Math.sin(angle);
      return { id, team: id.startsWith("a") ? 0 : 1, position: [x, 0.9, z], yaw_deg: Math.atan2(cx - x, -z) * 180 / Math.PI,
               pitch_deg: -5, alive: !(id === "b0" && k >= KILL_AT) };
    }),
    events: k === KILL_AT ? [{ kind: "kill", attacker: "a0", victim: "b0", weapon: "rl" }] : [],
  };
}

/** The same state as the SDK's frame options, built here from docs/engines.md's rules. */
function sdkFrame(s) {
  const transform = (p) => {
    const yaw = p.yaw_deg * Math.PI / 180;
    return { position: { x: p.position[0], y: p.position[1], z: p.position[2] }, rotation: { x: 0, y: Math.sin(yaw / 2), z: 0, w: Math.cos(yaw / 2) } };
  };
  return {
    targets: s.players.map((p) => ({ id: p.id, team: p.team, transform: transform(p), aimOffset: { y: 0.6 },
      mesh: { source: { case: "primitive", value: { shape: { case: "capsule", value: { radius: 0.3, height: 1.8 } } } } } })),
    states: s.players.filter((p) => p.alive).map((p) => ({ id: p.id, transform: transform(p) })),
    events: s.events.map((e) => ({ kind: pb.EventKind.EVENT_KILL, actorId: e.attacker, otherActorId: e.victim, label: e.weapon })),
  };
}

async function post(base, path, body) {
  const response = await fetch(base + path, { method: "POST", body: typeof body === "string" ? body : JSON.stringify(body) });
  return [response.status, await response.json()];
}

test("a posted game-state feed is answered with the program camera and shot", { timeout: 120_000 }, async () => {
  const bridge = spawn(process.execPath, ["examples/game_state_bridge.mjs", URL_, "--port", "0"], { stdio: ["ignore", "pipe", "inherit"] });
  try {
    const [line] = await once(createInterface({ input: bridge.stdout }), "line");
    const base = JSON.parse(line).listening;
    const states = Array.from({ length: 90 }, (_, k) => state(k));
    const answers = [];
    for (const s of states) {
      const [status, body] = await post(base, "/state", s);
      assert.equal(status, 200, JSON.stringify(body));
      answers.push(body);
    }
    // the same frames straight through the SDK
    const client = connect(URL_);
    const session = await client.createSession({ targets: sdkFrame(states[0]).targets, style: { rig: pb.Rig.MATCH } });
    const expected = [];
    for (const [k, s] of states.entries()) {
      const { states: objects, events } = sdkFrame(s);
      expected.push(await session.frame(k + 1, s.time_s, { states: objects, events }));
    }
    await session.close();
    client.close();
    assert.deepEqual(answers.map((a) => a.frame), states.map((_, k) => k + 1));
    for (const [k, u] of expected.entries()) {
      const a = answers[k];
      assert.deepStrictEqual(a.camera.position, [u.pose.position.x, u.pose.position.y, u.pose.position.z], `frame ${k + 1}`);
      assert.deepStrictEqual(a.camera.rotation, [u.pose.rotation.x, u.pose.rotation.y, u.pose.rotation.z, u.pose.rotation.w]);
      assert.deepStrictEqual([a.shot.subjects, a.shot.kind, a.cut], [[...u.shot.subjectIds], pb.ShotKind[u.shot.kind], u.cut]);
    }
    assert.ok(answers.every((a) => a.shot.subjects.every((id) => PLAYERS.includes(id)) && a.shot.kind.startsWith("SHOT_")));
    assert.ok(answers[0].cut && answers.at(-1).candidates.length > 0);
    // bad states: the reason, and the session goes on
    const bad = [
      ["{not json", 400, /not JSON/], [{ players: states[0].players }, 400, /time_s/],
      [{ ...state(90), players: [{ id: "a0", position: [0, "up", 0] }] }, 400, /position/],
      [{ ...state(90), events: [{ kind: "assist" }] }, 400, /kill/],
      [{ ...state(90), players: [...state(90).players, { id: "ghost", position: [0, 0, 0] }] }, 404, /ghost/],
    ];
    for (const [body, status, reason] of bad) {
      const [got, answer] = await post(base, "/state", body);
      assert.equal(got, status, JSON.stringify(answer));
      assert.match(answer.error, reason);
    }
    assert.equal((await post(base, "/state", state(91)))[0], 200);
    assert.deepEqual(await post(base, "/reset", {}), [200, { frames: 91 }]);
    assert.equal((await fetch(base + "/nowhere")).status, 404);
  } finally {
    bridge.kill("SIGTERM");
    await once(bridge, "exit");
  }
});
