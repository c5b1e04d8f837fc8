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
  DEFAULT_MAX_MESSAGE_BYTES, DEFAULT_TIMEOUT_MS, EncodedFrame, KEY_ENV, PACKED_WIDTH, PROTOCOL, PROTOCOL_HEADER,
  RETRYABLE, RETRY_DELAYS_MS, ROUTE_HEADER, encodeFrameUpdate, frameUpdate, parseUrl,
  type FrameOptions, type Packed, type StatesInit,
} from "./wire.js";
export * from "./convert.js";
export * as pb from "./gen/camdirector/v1/director_pb.js";
export { create, fromBinary, toBinary, toJson, fromJson } from "@bufbuild/protobuf";
