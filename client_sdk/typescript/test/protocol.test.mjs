// CreateSession says the protocol this SDK speaks, over gRPC and ZeroMQ alike: a recorded session
// (the Python side reads the client_protocol the server received from its recording, whose path is
// written to CAMDIRECTOR_TEST_OUT); a request that claims a newer protocol is refused
// FAILED_PRECONDITION with the server's words, and the client goes on to another session.
import assert from "node:assert/strict";
import { writeFileSync } from "node:fs";
import { test } from "node:test";
import { connect, DirectorError, PROTOCOL } from "../dist/index.js";
import { connectOptions, env, twoTargets } from "./helpers.mjs";

test("CreateSession says PROTOCOL; a newer claim is refused and the client goes on", async () => {
  const client = connect(env("CAMDIRECTOR_TEST_URL"), connectOptions());
  try {
    const request = twoTargets({ record: true });
    const recorded = await client.createSession(request);
    assert.equal(request.clientProtocol, 0, "the caller's request is not changed");
    await recorded.close();
    assert.ok(recorded.recordingPath, "the server records the session");

    await assert.rejects(client.createSession(twoTargets({ clientProtocol: PROTOCOL + 1 })), (e) => {
      assert.ok(e instanceof DirectorError, `not a DirectorError: ${e}`);
      assert.equal(e.code, "FAILED_PRECONDITION", e.message);
      for (const words of [`protocol ${PROTOCOL + 1}`, `protocol ${PROTOCOL}:`, "upgrade the server"]) {
        assert.ok(e.message.includes(words), `${JSON.stringify(e.message)} lacks ${JSON.stringify(words)}`);
      }
      return true;
    });

    const next = await client.createSession(twoTargets());
    assert.equal(await next.close(), 0n);
    writeFileSync(env("CAMDIRECTOR_TEST_OUT"), JSON.stringify({ recordingPath: recorded.recordingPath, protocol: PROTOCOL }));
  } finally {
    client.close();
  }
});
