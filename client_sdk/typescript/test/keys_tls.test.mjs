// Keys and TLS against a server with authentication on and gRPC over TLS (the test CA): the key
// on every call (given, or CAMDIRECTOR_KEY), refused keys answered at once and never tried again,
// the CA option, the hints when TLS is on one side only or the CA is unknown, no key shown.
import assert from "node:assert/strict";
import { test } from "node:test";
import { inspect } from "node:util";
import { connect, DirectorError, packStates } from "../dist/index.js";
import { collect, env, twoTargets } from "./helpers.mjs";

const URL_ = env("CAMDIRECTOR_TEST_URL"); // grpcs://127.0.0.1:PORT
const CA = env("CAMDIRECTOR_TEST_CA");
const ADMIN = env("CAMDIRECTOR_TEST_ADMIN_KEY");
const VIEWER = env("CAMDIRECTOR_TEST_VIEWER_KEY");

async function drive(client) {
  const session = await client.createSession(twoTargets({ seed: 2n }));
  await session.frame(1, 1 / 60, { packed: packStates(["a"], [0, 0.9, 0], [0, 0, 0, 1]) });
  const replies = await collect(session.stream([2, 3, 4].map((i) => session.frameUpdate(i, i / 60))));
  await session.updateStyle({ gazeRoomM: 0.5 });
  return [1 + replies.length, await session.close()];
}

test("a key opens sessions over TLS with the CA; CAMDIRECTOR_KEY stands in for it", async () => {
  const client = connect(URL_, { key: ADMIN, caFile: CA });
  try { assert.deepEqual(await drive(client), [4, 4n]); } finally { client.close(); }
  process.env.CAMDIRECTOR_KEY = ADMIN;
  const fromEnv = connect(URL_, { caFile: CA });
  try { assert.deepEqual(await drive(fromEnv), [4, 4n]); } finally { fromEnv.close(); delete process.env.CAMDIRECTOR_KEY; }
});

test("no key, an unknown key, a role without the verb: refused at once, the key never shown", async () => {
  const unknown = "cdk_000000000000_" + "f".repeat(43);
  for (const [key, code] of [[undefined, "UNAUTHENTICATED"], [unknown, "UNAUTHENTICATED"], [VIEWER, "PERMISSION_DENIED"]]) {
    const client = connect(URL_, { key, caFile: CA });
    const started = performance.now();
    await assert.rejects(client.createSession(twoTargets()), (e) => {
      assert.ok(e instanceof DirectorError);
      assert.equal(e.code, code, e.message);
      for (const secret of [unknown, VIEWER, ADMIN]) {
        assert.ok(!e.message.includes(secret) && !String(e.stack).includes(secret), "a key in an error");
      }
      return true;
    });
    assert.ok(performance.now() - started < 1000, "refused at once, not tried again");
    assert.ok(!inspect(client, { depth: 10, showHidden: true }).includes(ADMIN));
    client.close();
  }
  const admin = connect(URL_, { key: ADMIN, caFile: CA });
  const shown = inspect(admin, { depth: 10, showHidden: true }) + JSON.stringify(admin) + String(admin);
  assert.ok(!shown.includes(ADMIN), "the key in the client's inspect");
  const session = await admin.createSession(twoTargets());
  assert.ok(!(inspect(session, { depth: 10, showHidden: true }) + JSON.stringify(session)).includes(ADMIN), "the key in a session");
  await session.close();
  admin.close();
});

test("TLS on one side only, or a CA the client does not trust: UNAVAILABLE with a hint", async () => {
  const plain = connect(URL_.replace("grpcs://", "grpc://"), { key: ADMIN, timeoutMs: 3000 });
  await assert.rejects(plain.createSession(twoTargets()), (e) => {
    assert.ok(["UNAVAILABLE", "INTERNAL", "DEADLINE_EXCEEDED"].includes(e.code), `${e.code}: ${e.message}`);
    return true;
  });
  plain.close();
  const untrusted = connect(URL_, { key: ADMIN, timeoutMs: 3000 }); // the system's roots: not the test CA
  await assert.rejects(untrusted.createSession(twoTargets()), (e) => {
    assert.equal(e.code, "UNAVAILABLE", e.message);
    assert.match(e.message, /caFile/);
    return true;
  });
  untrusted.close();
  assert.throws(() => connect(URL_, { caFile: "/no/such/ca.pem" }), (e) => e.code === "INVALID_ARGUMENT");
});
