// Frame round trips through the TypeScript SDK, for load_tests/ts_sdk_bench.py:
//   node bench/frame_rtt.mjs URL CREATE_B64 FRAMES WARMUP
// One session; unary Frame calls one after another, then a StreamFrames call with one update in
// flight; both with packed transforms (packStates, Float64Array). Prints JSON: round trips, ms.
import { connect, fromBinary, packStates, pb } from "../dist/index.js";

const [url, createB64, framesArg, warmupArg] = process.argv.slice(2);
const frames = Number(framesArg), warmup = Number(warmupArg);
const ids = ["a", "b"];
const packedAt = (i) => {
  const t = i / 60;
  return packStates(ids, [Math.sin(t), 0.9, t, 3 - t, 0.9, 1], [0, Math.sin(t / 4), 0, Math.cos(t / 4), 0, 0, 0, 1]);
};

const client = connect(url);
const session = await client.createSession(fromBinary(pb.CreateSessionRequestSchema, Buffer.from(createB64, "base64")));
const unary = [];
let i = 1;
for (let k = 0; k < warmup + frames; k++, i++) {
  const t0 = process.hrtime.bigint();
  await session.frame(i, i / 60, { packed: packedAt(i) });
  if (k >= warmup) unary.push(Number(process.hrtime.bigint() - t0) / 1e6);
}
// streamed, one in flight: the next update is made when the last reply came
const stream = [];
let release, t0;
const first = i;
async function* updates() {
  for (let k = 0; k < warmup + frames; k++) {
    if (k > 0) await new Promise((resolve) => { release = resolve; });
    t0 = process.hrtime.bigint();
    const n = first + k;
    yield session.encodeFrame(n, n / 60, { packed: packedAt(n) });
  }
}
let k = 0;
for await (const _ of session.stream(updates())) {
  if (k++ >= warmup) stream.push(Number(process.hrtime.bigint() - t0) / 1e6);
  release?.();
}
await session.close();
client.close();
console.log(JSON.stringify({ unary, stream }));
