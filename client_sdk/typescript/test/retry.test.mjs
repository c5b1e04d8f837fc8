// Issue 40 in the TypeScript SDK, as in the Python SDK (tests/client_sdk/test_retry.py): retries
// within a window with jittered backoff, a hung node's frames tried again, and DATA_LOSS "resend
// from K" answered by sending the kept updates again. The backoff is checked with an injected
// clock and random source; the rest against a Director served in this process (grpc-js), which
// answers DATA_LOSS, UNAVAILABLE or nothing on demand, as a real server cannot be made to; over
// ZeroMQ, a ROUTER socket of this process that leaves the first frame unanswered.
// Needs no environment: tests/client_sdk/typescript/test_ts_retry.py runs it after the build.
import assert from "node:assert/strict";
import { createServer } from "node:net";
import { after, before, test } from "node:test";
import * as grpc from "@grpc/grpc-js";
import { Router } from "zeromq";
import {
  Backoff, DirectorError, SentHistory, connect, create, fromBinary, pb, resendFrom, retryPolicy, toBinary, withAnsweredFrame,
} from "../dist/index.js";
import { collect } from "./helpers.mjs";

/** A seeded source in [0, 1) (mulberry32), for the jitter. */
function seeded(seed) {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

test("backoff doubles from 100 ms with equal jitter up to the 500 ms cap", () => {
  const draws = seeded(7);
  const backoff = new Backoff(retryPolicy({ random: seeded(7) }), () => 5000);
  const delays = Array.from({ length: 7 }, () => backoff.nextDelayMs());
  const caps = [100, 200, 400, 500, 500, 500, 500];
  assert.deepEqual(delays, caps.map((cap) => cap * (0.5 + 0.5 * draws())));
  caps.forEach((cap, i) => assert.ok(cap / 2 <= delays[i] && delays[i] <= cap, `${delays[i]} for ${cap}`));
});

test("backoff stops when the window since the first failure is spent", () => {
  let nowMs = 100_000;
  const backoff = new Backoff(retryPolicy({ retryWindowMs: 2000, random: () => 1 }), () => nowMs);
  nowMs += 1950;
  assert.equal(backoff.nextDelayMs(), 50); // no wait past the window's end
  assert.equal(backoff.nextDelayMs(true), 0); // a DATA_LOSS resend: no wait, still counted
  nowMs += 50;
  assert.equal(backoff.nextDelayMs(), undefined);
  assert.equal(backoff.nextDelayMs(true), undefined);
});

test("a bad policy is refused, and the defaults are the issue's", () => {
  for (const bad of [{ retryWindowMs: -1 }, { frameTimeoutMs: 0 }, { resendHistoryFrames: -1 }, { maxBackoffMs: NaN }]) {
    const name = Object.keys(bad)[0];
    assert.throws(() => connect("grpc://127.0.0.1:1", { retry: bad }), (e) => e.code === "INVALID_ARGUMENT" && e.message.includes(name));
  }
  const policy = retryPolicy();
  assert.deepEqual([policy.retryWindowMs, policy.initialBackoffMs, policy.maxBackoffMs, policy.frameTimeoutMs, policy.resendHistoryFrames],
    [30_000, 100, 500, 3000, 600]);
  assert.equal(retryPolicy({ frameTimeoutMs: null }).frameTimeoutMs, null);
});

test("resendFrom reads the frame of a DATA_LOSS", () => {
  assert.equal(resendFrom(new DirectorError("DATA_LOSS", "state lost after frame 41: resend from 42")), 42n);
  assert.equal(resendFrom(new DirectorError("UNAVAILABLE", "resend from 42")), undefined);
  assert.equal(resendFrom(new DirectorError("DATA_LOSS", "lost")), undefined);
});

test("the sent history keeps the last updates and says when one is gone", () => {
  const encoded = (frame) => ({ frame: BigInt(frame), bytes: new Uint8Array([frame]) });
  const history = new SentHistory(3);
  const loss = new DirectorError("DATA_LOSS", "resend from 2");
  const sent = [1, 2, 3].map((f) => history.add(encoded(f)));
  assert.deepEqual(sent.map((s) => s.previousFrame), [0n, 1n, 2n]);
  assert.deepEqual(history.since(2n, undefined, loss), sent.slice(1));
  assert.deepEqual(history.since(2n, 2, loss), sent.slice(1, 2));
  history.add(encoded(5)); // frame 1 is dropped
  assert.deepEqual(history.since(2n, undefined, loss).map((s) => s.frame), [2n, 3n, 5n]);
  assert.throws(() => history.since(1n, undefined, loss),
    (e) => e.code === "DATA_LOSS" && e.message.includes("resend from 2") && e.message.includes("frame 1 is no longer among them"));
  const nothingKept = new SentHistory(0);
  nothingKept.add(encoded(1));
  assert.throws(() => nothingKept.since(1n, undefined, loss), /resendHistoryFrames/);
});

test("answered_frame is appended to an encoded update and read back", () => {
  const bytes = toBinary(pb.FrameUpdateSchema, create(pb.FrameUpdateSchema, { sessionId: "s", frame: 300n, answeredFrame: 7n }));
  for (const answered of [0n, 1n, 299n, 1n << 40n]) {
    assert.equal(fromBinary(pb.FrameUpdateSchema, withAnsweredFrame(bytes, answered)).answeredFrame, answered === 0n ? 7n : answered);
  }
});

/**
 * The Director's calls on a grpc-js server: every update is answered with its frame, except
 * - `frameFaults`: codes the next unary Frames end with, one each;
 * - `losses`: frame -> K, as a node whose restore ended at frame K - 1: that frame's call ends
 *   with DATA_LOSS "state lost after frame K-1: resend from K", and so does every call until frame K comes;
 * - `hangs`: frames left unanswered the first time they come (a stream stops answering at one);
 * - `answerDelayMs`: a stream's answers come this long after each other (a server with a backlog).
 * Records every update's [frame, answered_frame] (`seen`) and the frames answered (`answered`).
 */
class Director {
  frameFaults = [];
  losses = new Map();
  masking = false; // a stream's DATA_LOSS reaches the client as CANCELLED (HAProxy 2.6, haproxy/haproxy#1219)
  hangs = new Set();
  answerDelayMs = 0;
  awaiting = undefined;
  seen = [];
  answered = [];

  #lost(update) {
    const frame = Number(update.frame);
    this.seen.push([frame, Number(update.answeredFrame)]);
    if (this.losses.has(frame)) { this.awaiting = this.losses.get(frame); this.losses.delete(frame); }
    if (this.awaiting === undefined || frame === this.awaiting) {
      this.awaiting = undefined;
      return undefined;
    }
    return { code: grpc.status.DATA_LOSS, details: `state lost after frame ${this.awaiting - 1}: resend from ${this.awaiting}` };
  }

  #hung(update) {
    return this.hangs.delete(Number(update.frame));
  }

  #answer(update) {
    this.answered.push(Number(update.frame));
    return Buffer.from(toBinary(pb.CameraUpdateSchema, create(pb.CameraUpdateSchema, { frame: update.frame })));
  }

  handlers() {
    const decode = (bytes) => fromBinary(pb.FrameUpdateSchema, bytes);
    return {
      CreateSession: (_call, callback) => {
        callback(null, Buffer.from(toBinary(pb.CreateSessionResponseSchema, create(pb.CreateSessionResponseSchema, { sessionId: "s1" }))));
      },
      Frame: (call, callback) => {
        const update = decode(call.request);
        const fault = this.frameFaults.shift();
        if (fault !== undefined) return callback({ code: fault, details: "injected" });
        const lost = this.#lost(update);
        if (lost !== undefined) return callback(lost);
        if (this.#hung(update)) return; // never answered
        callback(null, this.#answer(update));
      },
      StreamFrames: (call) => {
        let hung = false;
        let ended = false;
        let pending = 0; // answers not yet written (answerDelayMs)
        let nextAnswerMs = 0;
        call.on("data", (bytes) => {
          if (hung) return;
          const update = decode(bytes);
          const lost = this.#lost(update);
          if (lost !== undefined) {
            hung = true;
            call.emit("error", this.masking ? { code: grpc.status.CANCELLED, details: "Received RST_STREAM with error code 8" } : lost);
            call.end();
            return;
          }
          hung = this.#hung(update);
          if (hung) return;
          if (this.answerDelayMs === 0) return call.write(this.#answer(update));
          nextAnswerMs = Math.max(nextAnswerMs, performance.now()) + this.answerDelayMs;
          pending += 1;
          setTimeout(() => {
            call.write(this.#answer(update));
            pending -= 1;
            if (ended && pending === 0) call.end();
          }, nextAnswerMs - performance.now());
        });
        call.on("end", () => {
          ended = true;
          if (!hung && pending === 0) call.end();
        });
        call.on("error", () => undefined);
      },
    };
  }
}

const raw = (bytes) => bytes;
const method = (name, requestStream, responseStream) => ({
  path: `/camdirector.v1.Director/${name}`, requestStream, responseStream,
  requestSerialize: raw, requestDeserialize: raw, responseSerialize: raw, responseDeserialize: raw,
});
const SERVICE = {
  CreateSession: method("CreateSession", false, false),
  Frame: method("Frame", false, false),
  StreamFrames: method("StreamFrames", true, true),
};

let server;
let director;
let url;

before(async () => {
  server = new grpc.Server();
  server.addService(SERVICE, {
    CreateSession: (call, callback) => director.handlers().CreateSession(call, callback),
    Frame: (call, callback) => director.handlers().Frame(call, callback),
    StreamFrames: (call) => director.handlers().StreamFrames(call),
  });
  const port = await new Promise((resolve, reject) => {
    server.bindAsync("127.0.0.1:0", grpc.ServerCredentials.createInsecure(), (error, bound) => (error ? reject(error) : resolve(bound)));
  });
  url = `grpc://127.0.0.1:${port}`;
});

after(() => server.forceShutdown());

/** A client of a fresh Director with `retry`, and a session; closed by the caller. */
async function open(retry = {}, options = {}) {
  director = new Director();
  const client = connect(url, { retry, ...options });
  return { client, session: await client.createSession({}) };
}

test("a new client reaches a server started where another client was refused", { timeout: 20_000 }, async () => {
  // A node restarted on its port, a port given out again. With grpc-js's process-wide subchannel
  // pool the new client took over the first one's connection, waiting to reconnect, and its first
  // call was refused (as in the Python SDK: tests/client_sdk/test_client.py).
  const port = await new Promise((resolve) => {
    const probe = createServer().listen(0, "127.0.0.1", () => {
      const { port: free } = probe.address();
      probe.close(() => resolve(free));
    });
  });
  const at = `grpc://127.0.0.1:${port}`;
  const stale = connect(at, { retry: { retryWindowMs: 0 } });
  const restarted = new grpc.Server();
  try {
    await assert.rejects(stale.createSession({}), (e) => e.code === "UNAVAILABLE");
    director = new Director();
    restarted.addService(SERVICE, { CreateSession: (call, callback) => director.handlers().CreateSession(call, callback) });
    await new Promise((resolve, reject) => {
      restarted.bindAsync(`127.0.0.1:${port}`, grpc.ServerCredentials.createInsecure(), (error) => (error ? reject(error) : resolve()));
    });
    const fresh = connect(at, { retry: { retryWindowMs: 0 } });
    try {
      assert.ok((await fresh.createSession({})).id);
    } finally {
      fresh.close();
    }
  } finally {
    stale.close();
    restarted.forceShutdown();
  }
});

const frames = (from, to) => Array.from({ length: to - from + 1 }, (_, i) => from + i);
const updates = (n) => frames(1, n).map((frame) => ({ frame: BigInt(frame) }));

test("a stream answered DATA_LOSS resends its kept updates", { timeout: 20_000 }, async () => {
  const { client, session } = await open();
  director.losses.set(30, 21); // a restore that lost frames 21..29, all answered already
  const answers = (await collect(session.stream(updates(40)))).map((a) => Number(a.frame));
  client.close();
  assert.deepEqual(answers, frames(1, 40)); // each once, in order: the resent ones' answers dropped
  assert.deepEqual(director.answered, [...frames(1, 29), ...frames(21, 40)]);
  assert.equal(session.answeredFrame, 40n);
  assert.ok(session.retries >= 1);
  // every update says the newest answer the client had when it was sent, never past its predecessor
  assert.ok(director.seen.every(([frame, answered]) => answered < frame), JSON.stringify(director.seen));
  assert.deepEqual(director.seen[0], [1, 0]);
  const lostAt = director.seen.findIndex(([frame]) => frame === 30);
  const resent = director.seen.slice(lostAt + 1, lostAt + 10);
  assert.deepEqual(resent, frames(21, 29).map((f) => [f, f - 1]));
});

test("a DATA_LOSS a balancer masks as CANCELLED is resent after one unary try", { timeout: 20_000 }, async () => {
  // before: each new stream resent its unanswered updates, was answered DATA_LOSS again and cut
  // again as CANCELLED, until the retry window ran out
  const { client, session } = await open({ retryWindowMs: 5000 });
  director.masking = true;
  director.losses.set(30, 21);
  const answers = (await collect(session.stream(updates(40)))).map((a) => Number(a.frame));
  client.close();
  assert.deepEqual(answers, frames(1, 40));
  // cut at 30 (CANCELLED); 30 alone as a unary Frame, answered DATA_LOSS whole; 21..29 resent
  // (their answers dropped), then 30, then the stream from 31 on
  assert.deepEqual(director.seen.map(([frame]) => frame), [...frames(1, 30), 30, ...frames(21, 30), ...frames(31, 40)]);
  assert.deepEqual(director.answered, [...frames(1, 29), ...frames(21, 40)]);
  assert.equal(session.retries, 2);
});

test("a unary frame answered DATA_LOSS resends its kept updates", { timeout: 20_000 }, async () => {
  const { client, session } = await open();
  for (const frame of frames(1, 5)) await session.frame(frame, frame / 60);
  director.losses.set(6, 3);
  assert.equal((await session.send({ frame: 6n })).frame, 6n);
  client.close();
  assert.deepEqual(director.answered, [1, 2, 3, 4, 5, 3, 4, 5, 6]);
  assert.deepEqual(director.seen.filter(([f]) => f === 6).map(([, a]) => a), [5, 5]);
  assert.equal(session.answeredFrame, 6n);
});

test("a DATA_LOSS beyond the kept updates is thrown, not skipped", { timeout: 20_000 }, async () => {
  const { client, session } = await open({ resendHistoryFrames: 10 });
  director.losses.set(30, 5);
  await assert.rejects(collect(session.stream(updates(40))),
    (e) => e.code === "DATA_LOSS" && /resend from 5 .*frame 5 is no longer among them/.test(e.message));
  client.close();
});

test("every failure is tried again until the window is spent", { timeout: 20_000 }, async () => {
  const { client, session } = await open({ retryWindowMs: 1500, maxBackoffMs: 100 }); // waits of 50 to 100 ms: 15 or more tries
  director.frameFaults = Array(1000).fill(grpc.status.UNAVAILABLE);
  await assert.rejects(session.frame(1, 0), (e) => e.code === "UNAVAILABLE");
  const tries = 1000 - director.frameFaults.length;
  assert.equal(session.retries, tries - 1);
  assert.ok(tries - 1 > 7, `${tries} tries`); // more than the 7 retries of the fixed sequence this replaced
  director.frameFaults = Array(3).fill(grpc.status.UNAVAILABLE);
  assert.equal((await session.frame(2, 0)).frame, 2n);
  assert.equal(session.retries, tries + 2); // a new window
  client.close();
});

test("a streamed frame left unanswered reopens the stream, every frame answered once", { timeout: 8000 }, async () => {
  const { client, session } = await open({ frameTimeoutMs: 300 });
  director.hangs.add(5); // the node stops answering at frame 5, its stream left open
  const answers = (await collect(session.stream(updates(10)))).map((a) => Number(a.frame));
  client.close();
  assert.deepEqual(answers, frames(1, 10));
  assert.equal(director.seen.filter(([f]) => f === 5).length, 2);
  assert.equal(session.retries, 1);
});

test("frames queued on a node that answers them, however long they wait, are not a hang", { timeout: 8000 }, async () => {
  const { client, session } = await open({ frameTimeoutMs: 300 });
  director.answerDelayMs = 100; // 12 frames sent at once: the last waits 1.2 s, answers 0.1 s apart
  const answers = (await collect(session.stream(updates(12)))).map((a) => Number(a.frame));
  client.close();
  assert.deepEqual(answers, frames(1, 12));
  assert.deepEqual(director.seen.map(([f]) => f), frames(1, 12)); // none sent again: the stream was never cut
  assert.equal(session.retries, 0);
});

test("a unary frame left unanswered is tried again, as UNAVAILABLE", { timeout: 4000 }, async () => {
  const { client, session } = await open({ frameTimeoutMs: 300 }, { timeoutMs: 10_000 });
  director.hangs.add(1);
  assert.equal((await session.frame(1, 0)).frame, 1n);
  assert.equal(session.retries, 1);
  client.close();
  const off = await open({ frameTimeoutMs: null, retryWindowMs: 0 }, { timeoutMs: 500 });
  director.hangs.add(1); // no frame timeout: the call's own deadline, not tried again
  await assert.rejects(off.session.frame(1, 0), (e) => e.code === "DEADLINE_EXCEEDED");
  off.client.close();
});

test("over ZeroMQ, a frame left unanswered is sent again on a new socket, as UNAVAILABLE", { timeout: 8000 }, async () => {
  const router = new Router({ linger: 0 });
  await router.bind("tcp://127.0.0.1:*");
  const seen = [];
  const serve = (async () => {
    for await (const [peer, method, request] of router) {
      let reply;
      if (method.toString() === "CreateSession") {
        reply = toBinary(pb.CreateSessionResponseSchema, create(pb.CreateSessionResponseSchema, { sessionId: "s1" }));
      } else {
        const update = fromBinary(pb.FrameUpdateSchema, request);
        seen.push(Number(update.frame));
        if (seen.length === 1) continue; // the hung node: never answered
        reply = toBinary(pb.CameraUpdateSchema, create(pb.CameraUpdateSchema, { frame: update.frame }));
      }
      await router.send([peer, "0", Buffer.from(reply)]);
    }
  })();
  const client = connect(router.lastEndpoint, { retry: { frameTimeoutMs: 300 }, timeoutMs: 10_000 });
  try {
    const session = await client.createSession({});
    const started = Date.now();
    assert.equal((await session.frame(1, 0)).frame, 1n);
    assert.ok(Date.now() - started < 5000, "waited for the call's own 10 s deadline");
    assert.equal(session.retries, 1);
    assert.deepEqual(seen, [1, 1]);
  } finally {
    client.close();
    router.close();
    await serve.catch(() => undefined);
  }
});
