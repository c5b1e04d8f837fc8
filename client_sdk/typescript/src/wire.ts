/**
 * What the transports share: endpoint URLs, the session and protocol headers, the retry policy
 * (backoff, the sent-update history a DATA_LOSS resend reads, per-frame deadlines),
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

/**
 * How a session rides out a lost node, a restarting balancer and a hung node (the Python SDK's
 * RetryPolicy). A call or stream that fails with a RETRYABLE code is tried again after waits that
 * start near `initialBackoffMs` and double up to `maxBackoffMs`, each with equal jitter (half
 * fixed, half drawn from `random`), until `retryWindowMs` has passed since its first failure; an
 * answer starts the count again. A stream is opened again from its first unanswered update.
 */
export interface RetryPolicy {
  /** A failing call is tried again until this long after its first failure, ms (default 30 000). */
  retryWindowMs: number;
  /** The first wait, ms (default 100); each next one doubles. */
  initialBackoffMs: number;
  /** The longest wait, ms (default 1000): a balancer back is found within it. */
  maxBackoffMs: number;
  /** gRPC: a frame (streamed, or a unary Frame) unanswered this long means a hung node: the call
   * is cancelled and tried again, ms (default 3000: a balancer's checks take a hung node out sooner); null: frames wait forever on a stream,
   * timeoutMs on a unary Frame. */
  frameTimeoutMs: number | null;
  /** Sent updates kept for a DATA_LOSS resend (default 600: 10 s at 60 Hz). */
  resendHistoryFrames: number;
  /** The jitter's source, in [0, 1) (default Math.random). */
  random: () => number;
}

export const DEFAULT_RETRY: Readonly<RetryPolicy> = Object.freeze({
  retryWindowMs: 30_000, initialBackoffMs: 100, maxBackoffMs: 500, frameTimeoutMs: 3000, resendHistoryFrames: 600,
  random: Math.random,
});

/** `given` over DEFAULT_RETRY; DirectorError(INVALID_ARGUMENT) for a setting out of range. */
export function retryPolicy(given: Partial<RetryPolicy> = {}): RetryPolicy {
  const policy: RetryPolicy = { ...DEFAULT_RETRY, ...given };
  for (const name of ["retryWindowMs", "initialBackoffMs", "maxBackoffMs"] as const) {
    if (!(policy[name] >= 0)) throw new DirectorError("INVALID_ARGUMENT", `retry.${name} must be >= 0, got ${policy[name]}`);
  }
  if (policy.frameTimeoutMs !== null && !(policy.frameTimeoutMs > 0)) {
    throw new DirectorError("INVALID_ARGUMENT", `retry.frameTimeoutMs must be > 0 or null, got ${policy.frameTimeoutMs}`);
  }
  if (!Number.isInteger(policy.resendHistoryFrames) || policy.resendHistoryFrames < 0) {
    throw new DirectorError("INVALID_ARGUMENT", `retry.resendHistoryFrames must be an integer >= 0, got ${policy.resendHistoryFrames}`);
  }
  if (typeof policy.random !== "function") throw new DirectorError("INVALID_ARGUMENT", "retry.random must be a function");
  return policy;
}

/** Channel options: the channel reconnects as often as calls are tried again (grpc-js's own first
 * wait is 1 s, growing to 120 s), pings its server every second, closing a connection that does
 * not answer within a second, and keeps its connections to itself: from grpc-js's process-wide
 * pool a new client took over another client's refused connection, waiting to reconnect, and its
 * first call was refused although a server listened there by then (test/retry.test.mjs). */
export function retryChannelOptions(policy: RetryPolicy): Record<string, number> {
  return {
    "grpc.initial_reconnect_backoff_ms": Math.max(1, Math.round(policy.initialBackoffMs)),
    "grpc.min_reconnect_backoff_ms": Math.max(1, Math.round(policy.initialBackoffMs)),
    "grpc.max_reconnect_backoff_ms": Math.max(1, Math.round(policy.maxBackoffMs)),
    "grpc.keepalive_time_ms": 1000,
    "grpc.keepalive_timeout_ms": 1000,
    "grpc.use_local_subchannel_pool": 1,
  };
}

/** The waits of one call's tries after its first failure (made then); see RetryPolicy. */
export class Backoff {
  readonly #startedMs: number;
  #tries = 0;

  constructor(private readonly policy: RetryPolicy, private readonly clock: () => number = () => performance.now()) {
    this.#startedMs = clock();
  }

  /** The wait before the next try, ms; undefined when the window is spent. `atOnce`: no wait (a
   * DATA_LOSS resend), the window still counted. */
  nextDelayMs(atOnce = false): number | undefined {
    const leftMs = this.policy.retryWindowMs - (this.clock() - this.#startedMs);
    if (leftMs <= 0) return undefined;
    if (atOnce) return 0;
    const capMs = Math.min(this.policy.maxBackoffMs, this.policy.initialBackoffMs * 2 ** this.#tries);
    this.#tries++;
    return Math.min(leftMs, capMs * (0.5 + 0.5 * this.policy.random()));
  }
}

/** The frame a DATA_LOSS answer asks the client to send again from ("state lost after frame N:
 * resend from N+1"); undefined for any other error. */
export function resendFrom(error: DirectorError): bigint | undefined {
  if (error.code !== "DATA_LOSS") return undefined;
  const found = /resend from (\d+)/.exec(error.message);
  return found ? BigInt(found[1]!) : undefined;
}

/** A frame update a session sent: its order among the session's updates, the frame of the one
 * sent before it (0: none), its frame, and its bytes (answered_frame not set). */
export interface Sent {
  readonly seq: number;
  readonly previousFrame: bigint;
  readonly frame: bigint;
  readonly bytes: Uint8Array;
}

/** The frame updates a session sent, oldest first, up to `limit` of them: what it sends again when
 * the server answers DATA_LOSS "resend from K". Shared by a session's unary calls and streams. */
export class SentHistory {
  readonly #kept: Sent[] = [];
  #seq = 0;
  #lastFrame = 0n;
  #droppedThrough = 0n; // the newest frame sent and no longer kept (0: none)

  constructor(readonly limit: number) {}

  /** Keeps the session's newest update and answers its entry. */
  add(update: EncodedFrame): Sent {
    const sent: Sent = { seq: ++this.#seq, previousFrame: this.#lastFrame, frame: update.frame, bytes: update.bytes };
    this.#lastFrame = update.frame;
    this.#kept.push(sent);
    while (this.#kept.length > this.limit) {
      const dropped = this.#kept.shift()!.frame;
      if (dropped > this.#droppedThrough) this.#droppedThrough = dropped;
    }
    return sent;
  }

  /** The kept updates from `frame` on, up to sequence number `throughSeq` (undefined: all);
   * throws `error` (the DATA_LOSS), with a word added, when an update from `frame` on is no longer kept. */
  since(frame: bigint, throughSeq: number | undefined, error: DirectorError): Sent[] {
    if (frame <= this.#droppedThrough) {
      throw new DirectorError(error.code, `${error.message} (this client kept the last ${this.limit} updates it sent, `
        + `resendHistoryFrames: frame ${frame} is no longer among them)`);
    }
    const last = throughSeq ?? this.#seq;
    return this.#kept.filter((s) => s.seq <= last && s.frame >= frame);
  }
}

/** When each frame in flight on a stream call was sent, oldest first, and when the last answer
 * came: a hung node is one that, with frames in flight, answers nothing for `timeoutMs` (since the
 * oldest unanswered frame was sent or, if later, since its last answer). Not the oldest frame's age
 * alone: a caller that sends faster than the server answers queues seconds of frames on a live
 * node, and cutting its call had answered frames resent and answered stale (issue 41). */
export class FrameDeadlines {
  readonly #sent: Array<[number, bigint]> = []; // (performance.now() when sent, frame)
  #answeredMs = -Infinity; // performance.now() of the last answer
  /** Set when a frame was left unanswered. */
  expired: DirectorError | undefined;

  constructor(readonly timeoutMs: number) {}

  sent(frame: bigint): void { this.#sent.push([performance.now(), frame]); }

  answered(): void {
    this.#answeredMs = performance.now();
    this.#sent.shift();
  }

  /** How long until the call's deadline (the whole timeout when no frame is in flight), ms; 0 when
   * it has passed, which sets `expired`. */
  waitMs(): number {
    const oldest = this.#sent[0];
    if (oldest === undefined) return this.timeoutMs;
    const leftMs = Math.max(oldest[0], this.#answeredMs) + this.timeoutMs - performance.now();
    if (leftMs > 0) return leftMs;
    this.expired = new DirectorError("UNAVAILABLE",
      `frame ${oldest[1]} was not answered within ${this.timeoutMs} ms (frameTimeoutMs) of the last answer: ` +
      "the node may be hung");
    return 0;
  }
}

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

const ANSWERED_FRAME_TAG = 9 << 3; // FrameUpdate.answered_frame, varint

/** A serialized FrameUpdate with answered_frame set: a scalar field given twice takes its last
 * value, so the field is appended (nothing when 0, the default). */
export function withAnsweredFrame(bytes: Uint8Array, answeredFrame: bigint): Uint8Array {
  if (answeredFrame === 0n) return bytes;
  const tail: number[] = [ANSWERED_FRAME_TAG];
  let value = answeredFrame;
  while (value > 0x7fn) { tail.push(Number(value & 0x7fn) | 0x80); value >>= 7n; }
  tail.push(Number(value));
  const out = new Uint8Array(bytes.length + tail.length);
  out.set(bytes, 0);
  out.set(tail, bytes.length);
  return out;
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
