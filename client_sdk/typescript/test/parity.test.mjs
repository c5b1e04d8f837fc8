// The TypeScript SDK's replies equal the Python SDK's bit for bit for the same session inputs
// (assert.deepStrictEqual compares numbers with Object.is: every double, -0 included), over the
// transport of CAMDIRECTOR_TEST_URL (gRPC, or ZeroMQ with CURVE and a key) as the Python side used.
import assert from "node:assert/strict";
import { test } from "node:test";
import { connect, encodeFrameUpdate } from "../dist/index.js";
import { collect, connectOptions, createRequest, env, frameFromJson, readData, replyJson } from "./helpers.mjs";

const data = readData();

test("an encoded FrameUpdate with packed transforms equals the Python SDK's bytes", () => {
  const e = data.toric.encoded;
  const mine = encodeFrameUpdate(e.sessionId, e.frame, e.timeS, { packed: { ids: e.ids, transforms: new Float64Array(e.transforms) } });
  assert.equal(Buffer.from(mine.bytes).toString("base64"), e.bytes);
  const fromFloats = encodeFrameUpdate(e.sessionId, e.frame, e.timeS, { packed: { ids: e.ids, transforms: e.transforms } });
  assert.deepEqual(fromFloats.bytes, mine.bytes);
});

test("toric rig, packed transforms, unary then streamed, then a style change", async () => {
  const { toric } = data;
  const client = connect(env("CAMDIRECTOR_TEST_URL"), connectOptions());
  try {
    const session = await client.createSession(createRequest(toric.create));
    const replies = [];
    for (const f of toric.frames.slice(0, toric.unary)) {
      replies.push(await session.frame(f.frame, f.timeS, { packed: { ids: f.ids, transforms: new Float64Array(f.transforms) } }));
    }
    const streamed = toric.frames.slice(toric.unary).map((f) =>
      session.encodeFrame(f.frame, f.timeS, { packed: { ids: f.ids, transforms: Float64Array.from(f.transforms) } }));
    replies.push(...await collect(session.stream(streamed)));
    await session.updateStyle({ screenA: { x: -0.5 }, screenB: { x: 0.5 } });
    replies.push(await session.frame(81, 81 / 60));
    assert.equal(await session.close(), 81n);
    assert.equal(session.retries, 0);
    assert.deepStrictEqual(replies.map(replyJson), toric.expected);
  } finally {
    client.close();
  }
});

test("RIG_MATCH: events, a take held then released, shots and candidates", async () => {
  const { match } = data;
  const client = connect(env("CAMDIRECTOR_TEST_URL"), connectOptions());
  try {
    const session = await client.createSession(createRequest(match.create));
    const replies = await collect(session.stream(async function* () { for (const f of match.parts[0]) yield frameFromJson(f); }()));
    const taken = await session.takeShot(match.take);
    assert.deepStrictEqual([[...taken.subjectIds], taken.kind, taken.held], match.taken);
    replies.push(...await collect(session.stream(match.parts[1].map(frameFromJson))));
    const released = await session.releaseShot();
    assert.deepStrictEqual([...(released?.subjectIds ?? [])], match.released);
    replies.push(...await collect(session.stream(match.parts[2].map(frameFromJson))));
    await session.close();
    assert.deepStrictEqual(replies.map(replyJson), match.expected);
    assert.ok(replies.some((u) => u.candidates.length > 0));
  } finally {
    client.close();
  }
});
