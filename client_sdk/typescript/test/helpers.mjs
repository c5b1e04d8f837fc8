// What the node tests share: the data the Python side wrote, and replies in the Python side's form.
import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { create, fromBinary, pb } from "../dist/index.js";

export const env = (name) => {
  const value = process.env[name];
  if (!value) throw new Error(`${name} is not set: run these tests from tests/client_sdk/typescript/test_node.py`);
  return value;
};

/** connect()'s options from CAMDIRECTOR_TEST_CONNECT (JSON), when set: a key, a CURVE server key. */
export const connectOptions = () => JSON.parse(process.env.CAMDIRECTOR_TEST_CONNECT || "{}");

export const readData = () => JSON.parse(readFileSync(env("CAMDIRECTOR_TEST_DATA"), "utf8"));

export const createRequest = (b64) => fromBinary(pb.CreateSessionRequestSchema, Buffer.from(b64, "base64"));

const pose = (p) => [p.position?.x ?? 0, p.position?.y ?? 0, p.position?.z ?? 0, p.rotation?.x ?? 0, p.rotation?.y ?? 0,
  p.rotation?.z ?? 0, p.rotation?.w ?? 0, p.verticalFovDeg];

/** A CameraUpdate as tests/client_sdk/typescript/test_node.py's reply_json writes it. */
export function replyJson(u) {
  return {
    frame: Number(u.frame), timeS: u.timeS, pose: u.pose ? pose(u.pose) : null, cut: u.cut, shotId: u.shotId,
    visibility: u.visibility, stale: u.stale, buffering: u.buffering, message: u.message,
    diagnostics: [u.diagnostics?.theta ?? 0, u.diagnostics?.phi ?? 0, u.diagnostics?.alpha ?? 0],
    shot: [[...(u.shot?.subjectIds ?? [])], u.shot?.kind ?? 0, u.shot?.reason ?? "", u.shot?.held ?? false],
    candidates: u.candidates.map((c) => [pose(c.pose), [...(c.shot?.subjectIds ?? [])], c.shot?.kind ?? 0, c.score]),
  };
}

/** A FrameUpdate from frame_json's form, built with the SDK's message types (sessionId left empty). */
export function frameFromJson(f) {
  return create(pb.FrameUpdateSchema, {
    frame: BigInt(f.frame), timeS: f.timeS,
    states: f.states.map((s) => ({
      id: s.id, transform: { position: { x: s.p[0], y: s.p[1], z: s.p[2] },
        rotation: s.q ? { x: s.q[0], y: s.q[1], z: s.q[2], w: s.q[3] } : undefined },
    })),
    events: f.events,
  });
}

export async function collect(iterable) {
  const out = [];
  for await (const item of iterable) out.push(item);
  return out;
}

const capsule = { source: { case: "primitive", value: { shape: { case: "capsule", value: { radius: 0.3, height: 1.8 } } } } };
const box = (x, y, z) => ({ source: { case: "primitive", value: { shape: { case: "box", value: { size: { x, y, z } } } } } });

/** tests/service/wire_client.py's two_target_request, in TypeScript. */
export function twoTargets(extra = {}) {
  return create(pb.CreateSessionRequestSchema, {
    targets: [
      { id: "a", mesh: capsule, transform: { position: { x: 0, y: 0.9, z: 0 } }, aimOffset: { x: 0, y: 0.6, z: 0 } },
      { id: "b", mesh: capsule, transform: { position: { x: 3, y: 0.9, z: 1 } }, aimOffset: { x: 0, y: 0.6, z: 0 } },
    ],
    objects: [
      { id: "pillar", mesh: box(1, 3, 1), transform: { position: { x: 1.5, y: 1.5, z: 4 } } },
      { id: "cart", mesh: box(1, 1, 1), transform: { position: { x: -2, y: 0.5, z: 2 } }, dynamic: true },
    ],
    ...extra,
  });
}

/** Closes the sessions, then checks that each was answered every frame of data once, in order, with
 * the poses of the undisturbed run (data.expected), and closed having answered them all. */
export async function assertUndisturbed(sessions, answers, data) {
  const closed = [];
  for (const s of sessions) closed.push(await s.close());
  const n = data.frames.length;
  for (const [k, s] of sessions.entries()) {
    assert.deepEqual(answers[k].map((u) => Number(u.frame)), Array.from({ length: n }, (_, i) => i + 1), s.id);
    assert.deepStrictEqual(answers[k].map(replyJson).map((r) => r.pose), data.expected.map((r) => r.pose), s.id);
  }
  assert.deepEqual(closed, sessions.map(() => BigInt(n)));
  return n;
}
