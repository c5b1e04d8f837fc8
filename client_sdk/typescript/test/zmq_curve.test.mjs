// ZeroMQ (tcp://) against a server with authentication on, whose socket is a CURVE server: the
// server key given as text or as its server.key file; a client without it, or with another
// server's key, is dropped without a word (DEADLINE_EXCEEDED with a hint); refused bearer keys
// answered with their codes; the keys never shown; a closed client answers CANCELLED.
import assert from "node:assert/strict";
import { test } from "node:test";
import { inspect } from "node:util";
import { curveKeyPair } from "zeromq";
import { connect, DirectorError, packStates } from "../dist/index.js";
import { collect, env, twoTargets } from "./helpers.mjs";

const URL_ = env("CAMDIRECTOR_TEST_URL"); // tcp://127.0.0.1:PORT
const SERVER_KEY = env("CAMDIRECTOR_TEST_ZMQ_SERVER_KEY");
const SERVER_KEY_FILE = env("CAMDIRECTOR_TEST_ZMQ_SERVER_KEY_FILE");
const ADMIN = env("CAMDIRECTOR_TEST_ADMIN_KEY");
const VIEWER = env("CAMDIRECTOR_TEST_VIEWER_KEY");
const OTHER_SERVER_KEY = curveKeyPair().publicKey; // a key of no server here

async function drive(client) {
  const session = await client.createSession(twoTargets({ seed: 3n }));
  await session.frame(1, 1 / 60, { packed: packStates(["a"], [0, 0.9, 0], [0, 0, 0, 1]) });
  const replies = await collect(session.stream([2, 3, 4].map((i) => session.frameUpdate(i, i / 60))));
  await session.updateStyle({ gazeRoomM: 0.5 });
  assert.deepEqual(replies.map((u) => Number(u.frame)), [2, 3, 4]);
  return [1 + replies.length, await session.close()];
}

test("CURVE with the server key as text or as its file, and a bearer key", async () => {
  for (const zmqServerKey of [SERVER_KEY, SERVER_KEY_FILE]) {
    const client = connect(URL_, { key: ADMIN, zmqServerKey });
    try { assert.deepEqual(await drive(client), [4, 4n]); } finally { client.close(); }
  }
});

test("no CURVE key, or another server's: no reply, DEADLINE_EXCEEDED saying what to check", async () => {
  for (const [zmqServerKey, hint] of [[undefined, /zmqServerKey/], [OTHER_SERVER_KEY, /public key/]]) {
    const client = connect(URL_, { key: ADMIN, zmqServerKey, timeoutMs: 1500 });
    await assert.rejects(client.createSession(twoTargets()), (e) => {
      assert.ok(e instanceof DirectorError);
      assert.equal(e.code, "DEADLINE_EXCEEDED", e.message);
      assert.match(e.message, hint);
      return true;
    });
    client.close();
  }
});

test("no key, an unknown key, a role without the verb: refused with their codes, the keys never shown", async () => {
  const unknown = "cdk_000000000000_" + "f".repeat(43);
  for (const [key, code] of [[undefined, "UNAUTHENTICATED"], [unknown, "UNAUTHENTICATED"], [VIEWER, "PERMISSION_DENIED"]]) {
    const client = connect(URL_, { key, zmqServerKey: SERVER_KEY });
    await assert.rejects(client.createSession(twoTargets()), (e) => {
      assert.ok(e instanceof DirectorError);
      assert.equal(e.code, code, e.message);
      for (const secret of [unknown, VIEWER, ADMIN]) assert.ok(!String(e.stack).includes(secret), "a key in an error");
      return true;
    });
    client.close();
  }
  const admin = connect(URL_, { key: ADMIN, zmqServerKey: SERVER_KEY });
  const session = await admin.createSession(twoTargets());
  const shown = inspect(admin, { depth: 10, showHidden: true }) + inspect(session, { depth: 10, showHidden: true });
  assert.ok(!shown.includes(ADMIN), "the key in inspect");
  admin.close();
  await assert.rejects(session.frame(1, 0), (e) => e.code === "CANCELLED" && /closed/.test(e.message));
});
