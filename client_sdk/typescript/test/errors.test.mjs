// Every kind of bad input answered with its code, as a DirectorError (code: the gRPC status name),
// and the session it was sent to goes on. Argument errors the SDK can see itself are refused
// before any call, with INVALID_ARGUMENT.
import assert from "node:assert/strict";
import { createServer } from "node:net";
import { test } from "node:test";
import { connect, create, DirectorError, packStates, pb } from "../dist/index.js";
import { collect, env, twoTargets } from "./helpers.mjs";

const URL_ = env("CAMDIRECTOR_TEST_URL");

async function expectCode(promiseOrFn, code, contains = "") {
  await assert.rejects(async () => (typeof promiseOrFn === "function" ? promiseOrFn() : promiseOrFn), (e) => {
    assert.ok(e instanceof DirectorError, `not a DirectorError: ${e}`);
    assert.equal(e.code, code, e.message);
    assert.ok(e.message.includes(contains), `${JSON.stringify(e.message)} lacks ${JSON.stringify(contains)}`);
    return true;
  });
}

const walkOne = (i) => packStates(["a"], [Math.sin(i / 60), 0.9, i / 60], [0, 0, 0, 1]);

test("bad sessions, frames, styles and takes", async () => {
  const client = connect(URL_);
  try {
    const session = await client.createSession(twoTargets({ seed: 1n }));
    await session.frame(1, 1 / 60, { packed: walkOne(1) });
    // CreateSession
    await expectCode(client.createSession({}), "INVALID_ARGUMENT");
    const nanTarget = twoTargets(); nanTarget.targets[0].transform.position.x = NaN;
    await expectCode(client.createSession(nanTarget), "INVALID_ARGUMENT", "targets[0].transform.position");
    const dup = twoTargets(); dup.targets[1].id = "a";
    await expectCode(client.createSession(dup), "INVALID_ARGUMENT", "used twice");
    await expectCode(client.createSession(twoTargets({ style: { mapResolution: 5 } })), "INVALID_ARGUMENT");
    const tracks = twoTargets({ levelId: "no-such-level", style: { rig: pb.Rig.TRACKS } }); tracks.targets.pop();
    await expectCode(client.createSession(tracks), "NOT_FOUND", "no-such-level");
    const big = twoTargets();
    big.objects.push(create(pb.SceneObjectSchema, { id: "huge", mesh: { source: { case: "triangles", value: { vertices: Array.from({ length: 9 * 6000 }, (_, i) => (i * 0.37) % 5), indices: Array.from({ length: 3 * 6000 }, (_, i) => i) } } } }));
    await expectCode(client.createSession(big), "RESOURCE_EXHAUSTED");
    const foreign = twoTargets(); foreign.objects.push({ id: "plain object in a message" });
    await expectCode(client.createSession(foreign), "INVALID_ARGUMENT", "CreateSessionRequest"); // refused by the SDK
    // Frame
    await expectCode(session.frame(2, 2 / 60, { states: [{ id: "ghost" }] }), "NOT_FOUND", "ghost");
    await expectCode(session.frame(2, 2 / 60, { states: [{ id: "pillar", transform: { position: { x: 1, y: 1, z: 1 } } }] }), "FAILED_PRECONDITION", "static");
    await expectCode(session.frame(2, 2 / 60, { packed: { ids: ["a"], transforms: new Float64Array([NaN, 0, 0, 0, 0, 0, 1, 1, 1, 1]) } }), "INVALID_ARGUMENT", "NaN");
    await expectCode(session.frame(2, 2 / 60, { packed: { ids: ["a"], transforms: new Float64Array([0, 0, 0, 0, 0, 0, 0, 1, 1, 1]) } }), "INVALID_ARGUMENT", "zero-length quaternion");
    await expectCode(session.frame(2, Number.POSITIVE_INFINITY), "INVALID_ARGUMENT");
    await expectCode(session.frame(2, 2 / 60, { packed: { ids: ["a", "b"], transforms: new Float64Array(10) } }), "INVALID_ARGUMENT", "20 doubles");
    await expectCode(() => session.frame(-1, 0), "INVALID_ARGUMENT");
    const stale = await session.frame(1, 1 / 60);
    assert.ok(stale.stale && stale.message, "a frame not newer than the last is answered stale");
    // UpdateStyle, TakeShot
    await expectCode(session.updateStyle({ screenA: { x: 3 } }), "INVALID_ARGUMENT");
    await expectCode(session.updateStyle({ rig: pb.Rig.MATCH }), "FAILED_PRECONDITION");
    await expectCode(session.takeShot(["nobody"]), "FAILED_PRECONDITION");
    // a bad frame on a stream ends that stream with its status; the session streams on
    const frames = [3, 4, 5].map((i) => session.frameUpdate(i, i / 60, i === 4 ? { states: [{ id: "ghost" }] } : { packed: walkOne(i) }));
    await expectCode(collect(session.stream(frames)), "NOT_FOUND", "ghost");
    await expectCode(collect(session.stream([session.frameUpdate(6, 0.1), { sessionId: "another", frame: 7n }])), "INVALID_ARGUMENT", "one session");
    const after = await collect(session.stream([8, 9].map((i) => session.encodeFrame(i, i / 60, { packed: walkOne(i) }))));
    assert.deepEqual(after.map((u) => u.frame), [8n, 9n]);
    // the caller's own iterator failing ends the stream with its error, not a gRPC code
    const mine = new Error("the game's feed broke");
    await assert.rejects(collect(session.stream((function* () { yield session.frameUpdate(10, 0.2); throw mine; })())), (e) => e === mine);
    assert.equal(session.retries, 0, "nothing above is tried again");
    await session.close();
    await expectCode(session.frame(11, 0.3), "NOT_FOUND", session.id);
    await expectCode(session.updateStyle({}), "NOT_FOUND");
  } finally {
    client.close();
  }
});

test("a match session's bad takes", async () => {
  const client = connect(URL_);
  try {
    const capsule = { source: { case: "primitive", value: { shape: { case: "capsule", value: { radius: 0.3, height: 1.8 } } } } };
    const players = ["a0", "b0"].map((id, i) => ({ id, team: i, mesh: capsule, transform: { position: { x: 2 * i, y: 0.9, z: 0 } } }));
    const session = await client.createSession({ targets: players, style: { rig: pb.Rig.MATCH } });
    await session.frame(1, 0);
    await expectCode(session.takeShot(["nobody"]), "NOT_FOUND");
    await expectCode(session.takeShot(["a0"], 99), "INVALID_ARGUMENT");
    await session.close();
  } finally {
    client.close();
  }
});

test("URLs, options, deadlines, unreachable servers and closed clients", async () => {
  for (const url of ["http://127.0.0.1:1", "127.0.0.1:50051", "udp://127.0.0.1:5555", "grpc://nohost", "tcp://nohost"]) {
    assert.throws(() => connect(url), (e) => e instanceof DirectorError && e.code === "INVALID_ARGUMENT", url);
  }
  assert.throws(() => connect(URL_, { caFile: "/etc/hosts" }), (e) => e.code === "INVALID_ARGUMENT" && /grpcs/.test(e.message));
  assert.throws(() => connect(URL_, { zmqServerKey: "x".repeat(40) }), (e) => e.code === "INVALID_ARGUMENT" && /tcp:\/\//.test(e.message));
  assert.throws(() => connect("tcp://127.0.0.1:5555", { caFile: "/etc/hosts" }), (e) => e.code === "INVALID_ARGUMENT" && /zmqServerKey/.test(e.message));
  for (const zmqServerKey of ["too short", "~".repeat(40), "/etc/hosts"]) {
    assert.throws(() => connect("tcp://127.0.0.1:5555", { zmqServerKey }), (e) => e.code === "INVALID_ARGUMENT", zmqServerKey);
  }
  assert.throws(() => connect(URL_, { timeoutMs: 0 }), (e) => e.code === "INVALID_ARGUMENT");
  assert.throws(() => connect(URL_, { key: "has space" }), (e) => e.code === "INVALID_ARGUMENT" && !e.message.includes("has space"));
  // nothing listens: UNAVAILABLE at the first call (CreateSession is never tried again)
  const port = await new Promise((resolve) => { const s = createServer().listen(0, "127.0.0.1", () => { const p = s.address().port; s.close(() => resolve(p)); }); });
  const nobody = connect(`grpc://127.0.0.1:${port}`);
  await expectCode(nobody.createSession(twoTargets()), "UNAVAILABLE");
  nobody.close();
  const hurried = connect(URL_, { timeoutMs: 1 });
  await expectCode(hurried.createSession(twoTargets()), "DEADLINE_EXCEEDED");
  hurried.close();
  const client = connect(URL_);
  const session = await client.createSession(twoTargets());
  client.close();
  await expectCode(session.frame(1, 0), "CANCELLED", "closed");
  await expectCode(client.createSession(twoTargets()), "CANCELLED", "closed");
});
