"""The TypeScript SDK's retry policy, hung-node deadline and DATA_LOSS resend (issue 40):
client_sdk/typescript/test/retry.test.mjs, which serves its own Director in Node (a real server
cannot be made to answer DATA_LOSS or hang on demand), after `npm run build`."""

from __future__ import annotations

from tests.client_sdk.typescript.test_node import built, node_test

__all__ = ["built"]  # the build fixture, used by the test below


def test_retry_window_backoff_frame_timeout_and_data_loss_resend(built):
    node_test("retry", timeout=120.0)  # fails the test when any Node test fails
