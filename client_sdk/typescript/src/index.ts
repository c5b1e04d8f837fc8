/**
 * camdirector TypeScript SDK: director sessions over gRPC, packed transforms, Unity and Unreal
 * conversions.
 *
 *     import { connect, packStates } from "@camdirector/client";
 *     const client = connect("grpc://127.0.0.1:50051", { key: process.env.CAMDIRECTOR_KEY });
 *     const session = await client.createSession({ targets: [...] });
 *     const update = await session.frame(1, 1 / 60, { packed: packStates(ids, positions, rotations) });
 *
 * `pb` is the wire contract's generated code (protobuf-es schemas and types, from proto/ at build time).
 */
export { connect, Client, Session, type ConnectOptions, type StreamInput } from "./client.js";
export { DirectorError, statusName, type StatusName } from "./errors.js";
export {
  Backoff, DEFAULT_MAX_MESSAGE_BYTES, DEFAULT_RETRY, DEFAULT_TIMEOUT_MS, EncodedFrame, FrameDeadlines, KEY_ENV,
  PACKED_WIDTH, PROTOCOL, PROTOCOL_HEADER, RETRYABLE, ROUTE_HEADER, SentHistory, encodeFrameUpdate, frameUpdate,
  parseUrl, resendFrom, retryChannelOptions, retryPolicy, withAnsweredFrame,
  type FrameOptions, type Packed, type RetryPolicy, type Sent, type StatesInit,
} from "./wire.js";
export * from "./convert.js";
export * as pb from "./gen/camdirector/v1/director_pb.js";
export { create, fromBinary, toBinary, toJson, fromJson } from "@bufbuild/protobuf";
