// A cluster node SIGKILLed under live TypeScript streams through the balancer (grpcs://, an engine
// key): once every stream has answered 40 frames this writes the session ids to
// CAMDIRECTOR_TEST_READY; the Python side (tests/client_sdk/typescript/test_node.py) kills the node
// holding the most of them and writes CAMDIRECTOR_TEST_KILLED. Every frame is answered once, in
// order, with the poses of an undisturbed run (the Python SDK's through the same balancer); the
// worst stall (the longest wait between two answers of one stream) is printed.
import assert from "node:assert/strict";
import { existsSync, readFileSync, writeFileSync } from "node:fs";
import { test } from "node:test";
import { setTimeout as sleep } from "node:timers/promises";
import { connect } from "../dist/index.js";
import { assertUndisturbed, connectOptions, createRequest, env, frameFromJson, readData } from "./helpers.mjs";

const data = readData();
const READY = env("CAMDIRECTOR_TEST_READY");
const KILLED = env("CAMDIRECTOR_TEST_KILLED");
const SESSIONS = 8; // spread over two nodes by their route keys: four or more on the one killed
const HOLD_AT = 250; // a stream waits here for the kill if it has not come yet

test("streams through the balancer survive the SIGKILL of a node", { timeout: 120_000 }, async () => {
  const client = connect(env("CAMDIRECTOR_TEST_URL"), connectOptions());
  const request = createRequest(data.create);
  const sessions = [];
  for (let i = 0; i < SESSIONS; i++) sessions.push(await client.createSession(request));
  const answers = sessions.map(() => []);
  const times = sessions.map(() => []);
  let killed = false;
  const ready = () => answers.every((a) => a.length >= 40);

  async function drive(k) {
    async function* updates() {
      for (const [i, f] of data.frames.entries()) {
        if (i >= 40 && !killed) await sleep(10); // slowly on until the kill...
        while (i >= HOLD_AT && !killed) await sleep(10); // ...and no further without it
        // then at most 200 a second: the engine key's tenant allows 240 (a bucket of one second's frames), and the
        // 260 frames after the kill sent at once outran it on a fast day (RESOURCE_EXHAUSTED on a surviving node)
        if (killed) await sleep(5);
        yield frameFromJson(f);
      }
    }
    for await (const answer of sessions[k].stream(updates())) {
      answers[k].push(answer);
      times[k].push(performance.now());
    }
  }

  async function kill() {
    while (!ready()) await sleep(5);
    writeFileSync(READY, JSON.stringify(sessions.map((s) => s.id)));
    while (!existsSync(KILLED)) await sleep(5);
    killed = true;
  }

  await Promise.all([kill(), ...sessions.map((_, k) => drive(k))]);
  const n = await assertUndisturbed(sessions, answers, data);
  client.close();
  const stalls = times.map((t) => Math.max(...t.slice(1).map((x, i) => x - t[i])) / 1000);
  const retries = sessions.map((s) => s.retries);
  const { sessions_on_killed: onKilled } = JSON.parse(readFileSync(KILLED, "utf8"));
  console.log(JSON.stringify({ sessions: SESSIONS, frames: n, sessions_on_killed: onKilled, retries,
    worst_stall_s: +Math.max(...stalls).toFixed(3), stalls_s: stalls.map((s) => +s.toFixed(3)) }));
  assert.ok(onKilled >= SESSIONS / 2, `the killed node held ${onKilled} of the ${SESSIONS} sessions`);
  assert.ok(retries.filter((r) => r > 0).length >= onKilled, `the streams of the killed node were not tried again: ${retries}`);
});
