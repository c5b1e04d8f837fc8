/**
 * What the transports share: endpoint URLs, the session and protocol headers, the retry policy,
 * and the FrameUpdate encoder with packed transforms copied as raw little-endian doubles.
 */
import { randomBytes } from "node:crypto";
import { create, toBinary, type MessageInitShape } from "@bufbuild/protobuf";
import { FrameUpdateSchema, type FrameUpdate, type ObjectState, type GameEvent, type ObjectStateSchema, type GameEventSchema } from "./gen/camdirector/v1/director_pb.js";
import { DirectorError, type StatusName } from "./errors.js";

/** Milliseconds a unary call waits for its reply before DEADLINE_EXCEEDED. */
export const DEFAULT_TIMEOUT_MS = 10_000;
/** gRPC send and receive limit, bytes: scenes with meshes exceed gRPC's default 4 MiB. */
export const DEFAULT_MAX_MESSAGE_BYTES = 64 * 1024 * 1024;
/** gRPC metadata on every call of a session, CreateSession included: a balancer routes a session's
 * calls to one node by a consistent hash of it (docs/scaling.md). */
export const ROUTE_HEADER = "x-camdirector-route";
/** The wire contract's revision this SDK speaks: sent on every gRPC call (PROTOCOL_HEADER) and, on
 * every transport, in CreateSessionRequest.clientProtocol. */
export const PROTOCOL_HEADER = "camdirector-protocol";
export const PROTOCOL = 1;
/** The environment variable the key comes from when `connect` is given none. */
export const KEY_ENV = "CAMDIRECTOR_KEY";
/** Doubles per id in FrameUpdate.packed_transforms: px, py, pz, qx, qy, qz, qw, sx, sy, sz. */
export const PACKED_WIDTH = 10;

/**
 * What a session's call or stream is tried again after: UNAVAILABLE (the server restoring the
 * session after its worker or node was lost, or restarting) and CANCELLED (a balancer resetting
 * the HTTP/2 stream of a node that died; a client cancels a call itself only when its caller has
 * stopped reading it, and then nothing is left to retry). Never UNAUTHENTICATED nor
 * PERMISSION_DENIED: a refused key would be refused again.
 */
export const RETRYABLE: ReadonlySet<StatusName> = new Set<StatusName>(["UNAVAILABLE", "CANCELLED"]);

/** Waits before the tries after a RETRYABLE answer, about 3 s in all (as the Python SDK). */
export const RETRY_DELAYS_MS: readonly number[] = [20, 50, 100, 200, 400, 800, 1500];

/** A session's ROUTE_HEADER value, picked by the client before the session exists. */
export function newRouteKey(): string {
  return randomBytes(16).toString("hex");
}

export interface Endpoint {
  transport: "grpc" | "zmq";
  /** "host:port", as gRPC dials it; the whole tcp:// URL for ZeroMQ. */
  address: string;
  tls: boolean;
}

/** `grpc://host:port`, `grpcs://host:port` (gRPC over TLS) or `tcp://host:port` (ZeroMQ);
 * DirectorError(INVALID_ARGUMENT) otherwise. */
export function parseUrl(url: string): Endpoint {
  const match = /^([a-z]+):\/\/(.+:\d+)$/.exec(url);
  if (!match) {
    throw new DirectorError("INVALID_ARGUMENT", `expected grpc://host:port, grpcs://host:port or tcp://host:port, got ${JSON.stringify(url)}`);
  }
  const [, scheme, address] = match;
  if (scheme === "grpc" || scheme === "grpcs") return { transport: "grpc", address: address!, tls: scheme === "grpcs" };
  if (scheme === "tcp") return { transport: "zmq", address: url, tls: false };
  throw new DirectorError("INVALID_ARGUMENT", `unknown scheme ${JSON.stringify(scheme)} in ${JSON.stringify(url)}: use grpc:// (gRPC), grpcs:// (gRPC over TLS) or tcp:// (ZeroMQ)`);
}

/** The key as given, else CAMDIRECTOR_KEY, else none; checked without ever showing it. */
export function resolveKey(key: string | undefined): string | undefined {
  let source = "key";
  if (key === undefined) {
    key = process.env[KEY_ENV] || undefined;
    source = `the ${KEY_ENV} environment variable`;
  }
  if (key === undefined) return undefined;
  if (typeof key !== "string" || !/^[!-~]+$/.test(key)) {
    throw new DirectorError("INVALID_ARGUMENT", `${source} must be non-empty printable ASCII without spaces (the key is not shown)`);
  }
  return key;
}

/** Object states of one frame: ObjectState messages (or their init shapes). */
export type StatesInit = ReadonlyArray<ObjectState | MessageInitShape<typeof ObjectStateSchema>>;

/** The bulk form of object states: n ids and n * 10 doubles (px, py, pz, qx, qy, qz, qw, sx, sy, sz). */
export interface Packed {
  ids: readonly string[];
  transforms: Float64Array | Float32Array | readonly number[];
}

export interface FrameOptions {
  states?: StatesInit;
  packed?: Packed;
  events?: ReadonlyArray<GameEvent | MessageInitShape<typeof GameEventSchema>>;
}

/** A FrameUpdate already serialized (Session.encodeFrame), for `frame` or `stream` without a copy. */
export class EncodedFrame {
  constructor(readonly bytes: Uint8Array, readonly frame: bigint) {}
}

const LITTLE_ENDIAN = new Uint8Array(new Uint16Array([1]).buffer)[0] === 1;
const PACKED_TRANSFORMS_TAG = (6 << 3) | 2; // FrameUpdate.packed_transforms, length-delimited

/** Packed transforms as little-endian float64 bytes: the array's own memory where it already is. */
export function packedBytes(nIds: number, transforms: Packed["transforms"]): Uint8Array {
  let doubles: Float64Array;
  if (transforms instanceof Float64Array) doubles = transforms;
  else if (transforms instanceof Float32Array) doubles = new Float64Array(transforms); // one native conversion
  else if (Array.isArray(transforms)) doubles = Float64Array.from(transforms);
  else throw new DirectorError("INVALID_ARGUMENT", "packed transforms must be a Float64Array, a Float32Array or an array of numbers");
  if (doubles.length !== PACKED_WIDTH * nIds) {
    throw new DirectorError("INVALID_ARGUMENT", `${nIds} packed ids need ${PACKED_WIDTH * nIds} doubles, got ${doubles.length}`);
  }
  const bytes = new Uint8Array(doubles.buffer, doubles.byteOffset, doubles.byteLength);
  if (LITTLE_ENDIAN) return bytes;
  const out = new Uint8Array(bytes.length); // big-endian hosts: swap each double
  const view = new DataView(out.buffer);
  for (let i = 0; i < doubles.length; i++) view.setFloat64(8 * i, doubles[i]!, true);
  return out;
}

function varintLength(value: number): number {
  let n = 1;
  while (value > 0x7f) { value = Math.floor(value / 128); n++; }
  return n;
}

function writeVarint(out: Uint8Array, at: number, value: number): number {
  while (value > 0x7f) { out[at++] = (value & 0x7f) | 0x80; value = Math.floor(value / 128); }
  out[at++] = value;
  return at;
}

export function toFrameNumber(frame: number | bigint): bigint {
  if (typeof frame === "bigint") {
    if (frame < 0n || frame >= 1n << 64n) throw new DirectorError("INVALID_ARGUMENT", `frame must be a uint64, got ${frame}`);
    return frame;
  }
  if (!Number.isSafeInteger(frame) || frame < 0) throw new DirectorError("INVALID_ARGUMENT", `frame must be a non-negative integer, got ${frame}`);
  return BigInt(frame);
}

/** A FrameUpdate message (states, events and packed transforms as given). */
export function frameUpdate(sessionId: string, frame: number | bigint, timeS: number, options: FrameOptions = {}): FrameUpdate {
  const msg = create(FrameUpdateSchema, {
    sessionId, frame: toFrameNumber(frame), timeS,
    states: options.states as ObjectState[] | undefined, events: options.events as GameEvent[] | undefined,
  });
  if (options.packed) {
    msg.packedIds = [...options.packed.ids];
    const bytes = packedBytes(msg.packedIds.length, options.packed.transforms);
    msg.packedTransforms = Array.from(new Float64Array(bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength)));
  }
  return msg;
}

/**
 * toBinary(frameUpdate(...)), cheaper: the head (id, frame, time, states, events, packed ids) goes
 * through protobuf-es, then the packed transforms are appended as one length-delimited field of
 * raw little-endian doubles (protobuf's packed encoding) with no per-float work. Parsers merge
 * fields in any order, so the head followed by field 6 is the one message.
 */
export function encodeFrameUpdate(sessionId: string, frame: number | bigint, timeS: number, options: FrameOptions = {}): EncodedFrame {
  const number = toFrameNumber(frame);
  let head: Uint8Array;
  try {
    head = toBinary(FrameUpdateSchema, create(FrameUpdateSchema, {
      sessionId, frame: number, timeS,
      states: options.states as ObjectState[] | undefined, events: options.events as GameEvent[] | undefined,
      packedIds: options.packed ? [...options.packed.ids] : [],
    }));
  } catch (error) {
    throw new DirectorError("INVALID_ARGUMENT", `not a valid camdirector.v1.FrameUpdate: ${(error as Error).message}`);
  }
  if (!options.packed) return new EncodedFrame(head, number);
  const body = packedBytes(options.packed.ids.length, options.packed.transforms);
  if (body.length === 0) return new EncodedFrame(head, number);
  const out = new Uint8Array(head.length + 1 + varintLength(body.length) + body.length);
  out.set(head, 0);
  out[head.length] = PACKED_TRANSFORMS_TAG;
  const at = writeVarint(out, head.length + 1, body.length);
  out.set(body, at);
  return new EncodedFrame(out, number);
}

export function sleep(ms: number): Promise<void> {
  return new Promise((resolve) => setTimeout(resolve, ms));
}
