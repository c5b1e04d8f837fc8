// A worker SIGKILLed under live TypeScript streams (SIGSTOP, 0.1 s, SIGKILL, as
// ServerProcess.kill_worker_mid_request): the same session ids go on, every frame answered once,
// in order, with the poses of an undisturbed run (the Python SDK's, same inputs).
import assert from "node:assert/strict";
import { test } from "node:test";
import { setTimeout as sleep } from "node:timers/promises";
import { connect } from "../dist/index.js";
import { assertUndisturbed, createRequest, env, frameFromJson, readData } from "./helpers.mjs";

const data = readData();
const WORKER = Number(env("CAMDIRECTOR_TEST_WORKER_PID"));
const SESSIONS = 4; // the server deals sessions to its two workers in turn: two on the killed one

test("streams survive a worker's SIGKILL", { timeout: 60_000 }, async () => {
  const client = connect(env("CAMDIRECTOR_TEST_URL"));
  const request = createRequest(data.create);
  const sessions = [];
  for (let i = 0; i < SESSIONS; i++) sessions.push(await client.createSession(request));
  const answers = sessions.map(() => []);
  let running = false;
  const ready = () => answers.every((a) => a.length >= 40);

  async function drive(k) {
    async function* updates() {
      for (const [i, f] of data.frames.entries()) {
        await sleep(running || i < 40 ? 0 : 5); // slow down there, until the kill
        yield frameFromJson(f);
      }
    }
    for await (const answer of sessions[k].stream(updates())) {
      answers[k].push(answer);
      if (!running && ready()) running = true;
    }
  }

  async function kill() {
    while (!ready()) await sleep(2);
    process.kill(WORKER, "SIGSTOP");
    await sleep(100);
    process.kill(WORKER, "SIGKILL");
    running = true;
  }

  const started = performance.now();
  await Promise.all([kill(), ...sessions.map((_, k) => drive(k))]);
  const seconds = (performance.now() - started) / 1000;
  const n = await assertUndisturbed(sessions, answers, data);
  client.close();
  const retries = sessions.map((s) => s.retries);
  console.log(JSON.stringify({ sessions: SESSIONS, frames: n, seconds: +seconds.toFixed(2), retries }));
  assert.ok(retries.some((r) => r > 0), `no stream was tried again: ${retries}`);
});
