/**
 * The client: sessions over gRPC (`grpc://host:port`, `grpcs://host:port` over TLS; transport.ts)
 * or ZeroMQ (`tcp://host:port`; zmq_transport.ts), the Python SDK's behaviour
 * (client_sdk/python/camdirector_client/client.py):
 *
 * - every gRPC call of a session carries its route key (`x-camdirector-route`, picked before
 *   CreateSession and sent with it too), the protocol header and the key (`authorization`); a
 *   ZeroMQ request carries the key in its third frame;
 * - CreateSession says the protocol this SDK speaks (`clientProtocol`, where the request says
 *   none) on both transports: a server that speaks an older one refuses it FAILED_PRECONDITION;
 * - a call answered UNAVAILABLE or CANCELLED (a server restoring the session after its worker or
 *   node was lost; a balancer resetting the stream of a node that died) is tried again with the
 *   same session id, after 20 ms ... 1.5 s; a stream is opened again from its first unanswered
 *   update; UNAUTHENTICATED and PERMISSION_DENIED are never tried again;
 * - unary calls have a deadline (timeoutMs); StreamFrames has none; over ZeroMQ a stream is one
 *   Frame request per update, each with the deadline;
 * - the key is never logged, shown by util.inspect nor put in an error message.
 */
import { inspect } from "node:util";
import type * as grpc from "@grpc/grpc-js";
import { create, toBinary, type DescMessage, type MessageInitShape, type MessageShape } from "@bufbuild/protobuf";
import {
  CameraUpdateSchema, CloseSessionRequestSchema, CloseSessionResponseSchema, CreateSessionRequestSchema,
  CreateSessionResponseSchema, FrameUpdateSchema, StyleSchema, TakeShotRequestSchema, TakeShotResponseSchema,
  UpdateStyleRequestSchema, UpdateStyleResponseSchema,
  type CameraUpdate, type FrameUpdate, type ShotInfo, type ShotKind, type Style,
} from "./gen/camdirector/v1/director_pb.js";
import { DirectorError, statusName } from "./errors.js";
import { GrpcTransport, type Transport } from "./transport.js";
import {
  DEFAULT_MAX_MESSAGE_BYTES, DEFAULT_TIMEOUT_MS, EncodedFrame, PROTOCOL, RETRYABLE, RETRY_DELAYS_MS,
  encodeFrameUpdate, frameUpdate, newRouteKey, parseUrl, resolveKey, sleep, type FrameOptions,
} from "./wire.js";
import { ZmqTransport, curveServerKey } from "./zmq_transport.js";

export interface ConnectOptions {
  /** The API key: `authorization: Bearer KEY` on every gRPC call, the third frame of every ZeroMQ
   * request. Default: CAMDIRECTOR_KEY, else none. */
  key?: string;
  /** grpcs:// only: PEM file of the authorities to trust for the server's certificate; default the system's roots. */
  caFile?: string;
  /** tcp:// only: the server's CURVE public key (40 characters of Z85 text, its ready line's
   * `zmq_server_key`) or the path of its `DIR/zmq/server.key`. Given, the sockets are CURVE clients
   * (encrypted, with a key pair made for this client); a server with authentication on needs it. */
  zmqServerKey?: string;
  /** Milliseconds a unary call (over ZeroMQ: any request) waits for its reply before DEADLINE_EXCEEDED (default 10 000). */
  timeoutMs?: number;
  /** gRPC send and receive limit, bytes (default 64 MiB). */
  maxMessageBytes?: number;
  /** More grpc-js channel options; they override the ones above. */
  channelOptions?: grpc.ChannelOptions;
}

type Init<D extends DescMessage> = MessageShape<D> | MessageInitShape<D>;
/** What `Session.stream` takes: FrameUpdate messages (or their init shapes; an empty sessionId gets
 * the session's) or frames already encoded by `Session.encodeFrame`. */
export type StreamInput = FrameUpdate | MessageInitShape<typeof FrameUpdateSchema> | EncodedFrame;

/** `init` as the message of `schema`, serialized; DirectorError(INVALID_ARGUMENT) when it can not be. */
function encode<D extends DescMessage>(schema: D, init: Init<D>): Uint8Array {
  try {
    const msg = (init as { $typeName?: string }).$typeName === schema.typeName
      ? (init as MessageShape<D>) : create(schema, init as MessageInitShape<D>);
    return toBinary(schema, msg);
  } catch (error) {
    throw new DirectorError("INVALID_ARGUMENT", `not a valid ${schema.typeName}: ${(error as Error).message}`);
  }
}

/** `update` serialized, its empty sessionId given `sessionId`'s; DirectorError(INVALID_ARGUMENT)
 * when it is not a FrameUpdate. */
function encodeInput(update: StreamInput, sessionId: string): EncodedFrame {
  if (update instanceof EncodedFrame) return update;
  let msg: FrameUpdate;
  try {
    msg = (update as FrameUpdate).$typeName === "camdirector.v1.FrameUpdate"
      ? (update as FrameUpdate) : create(FrameUpdateSchema, update as MessageInitShape<typeof FrameUpdateSchema>);
  } catch (error) {
    throw new DirectorError("INVALID_ARGUMENT", `not a valid camdirector.v1.FrameUpdate: ${(error as Error).message}`);
  }
  if (!msg.sessionId) msg.sessionId = sessionId;
  return new EncodedFrame(encode(FrameUpdateSchema, msg), msg.frame);
}

/** The caller's updates for a stream that may take several gRPC calls (the Python SDK's
 * _Resumable): a call that ended with a RETRYABLE code is followed by one that sends its
 * unanswered updates again, then goes on with the caller's. Updates read from the caller's
 * iterator join one queue (read, not yet answered), one read under way at a time whichever call
 * asked for it, so an update read as a call ends goes to the next call, never lost. */
class Resumable {
  readonly #source: AsyncIterator<StreamInput> | Iterator<StreamInput>;
  #pull: Promise<void> | undefined;
  readonly #queue: EncodedFrame[] = []; // #queue[i] is update number #base + i
  #base = 0;
  error: unknown = undefined;
  failed = false;
  done = false;

  constructor(updates: AsyncIterable<StreamInput> | Iterable<StreamInput>, private readonly sessionId: string) {
    this.#source = Symbol.asyncIterator in updates
      ? (updates as AsyncIterable<StreamInput>)[Symbol.asyncIterator]()
      : (updates as Iterable<StreamInput>)[Symbol.iterator]();
  }

  /** Number of the oldest unanswered update: where a new call starts. */
  get first(): number { return this.#base; }

  /** Update number `i` (from `first` on), reading the caller's iterator as needed; undefined at its end. */
  async get(i: number): Promise<EncodedFrame | undefined> {
    while (i - this.#base >= this.#queue.length) {
      if (this.done || this.failed) return undefined;
      this.#pull ??= this.#read().finally(() => { this.#pull = undefined; });
      await this.#pull;
    }
    return this.#queue[i - this.#base];
  }

  async #read(): Promise<void> {
    try {
      const result = await this.#source.next();
      if (result.done) this.done = true;
      else this.#queue.push(encodeInput(result.value, this.sessionId));
    } catch (error) {
      this.error = error;
      this.failed = true;
    }
  }

  /** The oldest unanswered update was answered. */
  answered(): void {
    this.#queue.shift();
    this.#base++;
  }

  /** The stream is over: the caller's iterator is told (not waited for: it may be in a read). */
  close(): void {
    const source = this.#source;
    if (!this.done && !this.failed && typeof source.return === "function") {
      Promise.resolve().then(() => source.return!()).catch(() => undefined);
    }
  }
}

/** One director session. Calls answered UNAVAILABLE or CANCELLED are tried again (module comment). */
export class Session {
  /** Calls and streams tried again after a RETRYABLE answer. */
  retries = 0;
  #closedFrames: bigint | undefined;

  constructor(private readonly transport: Transport, readonly id: string, readonly recordingPath: string,
              /** The x-camdirector-route key of every call of this session. */ readonly route: string) {}

  /** The wait before the next try after `error`, counted; throws `error` when not to be tried again. */
  #retryAfter(error: unknown, tries: { n: number }): number {
    const e = this.transport.error(error);
    const delay = RETRYABLE.has(e.code) && !this.transport.closed ? RETRY_DELAYS_MS[tries.n++] : undefined;
    if (delay === undefined) throw e;
    this.retries++;
    return delay;
  }

  async #retrying<D extends DescMessage>(method: string, request: Uint8Array, response: D): Promise<MessageShape<D>> {
    const tries = { n: 0 };
    for (;;) {
      try {
        return await this.transport.unary(method, request, response, this.route);
      } catch (error) {
        await sleep(this.#retryAfter(error, tries));
      }
    }
  }

  /** A FrameUpdate message for this session (to feed `stream`). */
  frameUpdate(frame: number | bigint, timeS: number, options: FrameOptions = {}): FrameUpdate {
    return frameUpdate(this.id, frame, timeS, options);
  }

  /** This session's FrameUpdate serialized, packed transforms copied as raw doubles (for `stream`). */
  encodeFrame(frame: number | bigint, timeS: number, options: FrameOptions = {}): EncodedFrame {
    return encodeFrameUpdate(this.id, frame, timeS, options);
  }

  /** Sends one frame (the unary Frame RPC) and waits for its camera. `frame`: strictly increasing;
   * `timeS`: game time, non-decreasing; `packed`: packStates(...) or { ids, transforms }. */
  frame(frame: number | bigint, timeS: number, options: FrameOptions = {}): Promise<CameraUpdate> {
    let encoded: EncodedFrame;
    try { encoded = encodeFrameUpdate(this.id, frame, timeS, options); } catch (error) { return Promise.reject(error); }
    return this.#retrying("Frame", encoded.bytes, CameraUpdateSchema);
  }

  /** Sends a prebuilt FrameUpdate (its sessionId filled in when empty), or an EncodedFrame. */
  send(update: StreamInput): Promise<CameraUpdate> {
    let bytes: Uint8Array;
    try { bytes = encodeInput(update, this.id).bytes; } catch (error) { return Promise.reject(error); }
    return this.#retrying("Frame", bytes, CameraUpdateSchema);
  }

  /**
   * One CameraUpdate per update, in order, as they come: over gRPC one StreamFrames call, updates
   * written as the stream has room; over ZeroMQ one Frame request per update. `updates` may be sync or async. Leaving the loop early (break, return)
   * cancels the call. A call ended by UNAVAILABLE or CANCELLED is opened again with its unanswered
   * updates first.
   */
  async *stream(updates: AsyncIterable<StreamInput> | Iterable<StreamInput>): AsyncGenerator<CameraUpdate, void, undefined> {
    const feed = new Resumable(updates, this.id);
    const tries = { n: 0 };
    try {
      while (!this.transport.streams) { // ZeroMQ: one Frame request per update, each tried again as `frame`
        const encoded = await feed.get(feed.first);
        if (encoded === undefined) {
          if (feed.failed) throw feed.error;
          return;
        }
        const reply = await this.#retrying("Frame", encoded.bytes, CameraUpdateSchema);
        feed.answered();
        yield reply;
      }
      for (;;) {
        const call = this.transport.stream(this.route);
        let over = false; // this call ended: its writer stops
        const end = () => { over = true; };
        call.on("status", end);
        call.on("error", end);
        const writer = (async () => {
          for (let i = feed.first; ; i++) {
            const encoded = await feed.get(i);
            if (over) return;
            if (encoded === undefined) {
              if (feed.failed) call.cancel(); // the caller's iterator threw: raised below
              else call.end();
              return;
            }
            if (!call.write(encoded.bytes)) await drained(call, () => over);
          }
        })();
        try {
          for await (const reply of call as AsyncIterable<CameraUpdate>) {
            feed.answered();
            tries.n = 0; // answered again: a later loss gets every try anew
            yield reply;
          }
          if (feed.failed) throw feed.error;
          return;
        } catch (error) {
          if (feed.failed) throw feed.error; // the caller's iterator failed: grpc saw only a cancel
          if (error instanceof DirectorError) throw error;
          const delay = this.#retryAfter(error, tries); // throws when not to be tried again
          over = true;
          call.cancel();
          await sleep(delay);
        } finally {
          over = true;
          call.cancel();
          void writer;
        }
      }
    } finally {
      feed.close();
    }
  }

  /** Replaces the whole style from the next frame on (unset fields take their defaults). */
  async updateStyle(style: Init<typeof StyleSchema>): Promise<void> {
    const request = encode(UpdateStyleRequestSchema, { sessionId: this.id, style: style as Style });
    await this.#retrying("UpdateStyle", request, UpdateStyleResponseSchema);
  }

  /** A human director's shot in a RIG_MATCH session: `subjectIds` as `kind` (0: a duel for two, a
   * follow for one, a group for more), held until `releaseShot`. Answers the shot now held. */
  async takeShot(subjectIds: readonly string[], kind: ShotKind | number = 0): Promise<ShotInfo | undefined> {
    const request = encode(TakeShotRequestSchema, { sessionId: this.id, subjectIds: [...subjectIds], kind: kind as ShotKind });
    return (await this.#retrying("TakeShot", request, TakeShotResponseSchema)).shot;
  }

  /** Gives the program back to the director (TakeShot with release); answers the (empty) shot. */
  async releaseShot(): Promise<ShotInfo | undefined> {
    const request = encode(TakeShotRequestSchema, { sessionId: this.id, release: true });
    return (await this.#retrying("TakeShot", request, TakeShotResponseSchema)).shot;
  }

  /** Closes the session on the server; answers how many frames it answered. Idempotent. */
  async close(): Promise<bigint> {
    if (this.#closedFrames === undefined) {
      const request = toBinary(CloseSessionRequestSchema, create(CloseSessionRequestSchema, { sessionId: this.id }));
      this.#closedFrames = (await this.#retrying("CloseSession", request, CloseSessionResponseSchema)).frames;
    }
    return this.#closedFrames;
  }

  async [Symbol.asyncDispose](): Promise<void> {
    try { await this.close(); } catch { /* best effort */ }
  }
}

function drained(call: grpc.ClientDuplexStream<Uint8Array, CameraUpdate>, over: () => boolean): Promise<void> {
  if (over()) return Promise.resolve();
  return new Promise((resolve) => {
    const done = () => { call.off("drain", done); call.off("status", done); call.off("error", done); resolve(); };
    call.on("drain", done); call.on("status", done); call.on("error", done);
  });
}

/** A connection to a director server; see `connect`. */
export class Client {
  readonly #transport: Transport;

  constructor(transport: Transport, readonly url: string) {
    this.#transport = transport;
  }

  /** Opens a session from a CreateSessionRequest (or its init shape). CreateSession is not tried
   * again (a second session could be made); it carries the new session's route key, and says
   * PROTOCOL in `clientProtocol` where the request leaves it 0 (on a shallow copy: the caller's
   * request is not changed). */
  async createSession(request: Init<typeof CreateSessionRequestSchema>): Promise<Session> {
    const said = request.clientProtocol ? request : { ...request, clientProtocol: PROTOCOL };
    const bytes = encode(CreateSessionRequestSchema, said);
    const route = newRouteKey();
    const response = await this.#transport.unary("CreateSession", bytes, CreateSessionResponseSchema, route);
    return new Session(this.#transport, response.sessionId, response.recordingPath, route);
  }

  /** Closes the channel. Sessions stay open on the server until their timeout. */
  close(): void {
    this.#transport.close();
  }

  [Symbol.dispose](): void {
    this.close();
  }

  [inspect.custom](): string {
    return `Client(${JSON.stringify(this.url)})`;
  }
}

/**
 * A Client for `grpc://host:port`, `grpcs://host:port` (TLS) or `tcp://host:port` (ZeroMQ).
 * Connecting is lazy: an unreachable server shows at the first call (UNAVAILABLE over gRPC,
 * DEADLINE_EXCEEDED over ZeroMQ), and so does a refused key (UNAUTHENTICATED, PERMISSION_DENIED).
 * Bad options throw DirectorError(INVALID_ARGUMENT).
 */
export function connect(url: string, options: ConnectOptions = {}): Client {
  const endpoint = parseUrl(url);
  const timeoutMs = options.timeoutMs ?? DEFAULT_TIMEOUT_MS;
  if (!(timeoutMs > 0)) throw new DirectorError("INVALID_ARGUMENT", `timeoutMs must be > 0, got ${timeoutMs}`);
  const key = resolveKey(options.key);
  if (options.caFile !== undefined && !endpoint.tls) {
    const instead = endpoint.transport === "zmq" ? "ZeroMQ is encrypted with CURVE: give zmqServerKey" : "use grpcs://";
    throw new DirectorError("INVALID_ARGUMENT", `caFile is for grpcs:// URLs (gRPC over TLS); ${instead}`);
  }
  if (options.zmqServerKey !== undefined && endpoint.transport !== "zmq") {
    throw new DirectorError("INVALID_ARGUMENT", "zmqServerKey is for tcp:// URLs (ZeroMQ); gRPC is encrypted with TLS: use grpcs://");
  }
  if (endpoint.transport === "zmq") {
    const serverKey = options.zmqServerKey === undefined ? undefined : curveServerKey(options.zmqServerKey);
    return new Client(new ZmqTransport(endpoint.address, key, serverKey, timeoutMs), url);
  }
  const maxBytes = options.maxMessageBytes ?? DEFAULT_MAX_MESSAGE_BYTES;
  if (!(maxBytes > 0)) throw new DirectorError("INVALID_ARGUMENT", `maxMessageBytes must be > 0, got ${maxBytes}`);
  const channelOptions: grpc.ChannelOptions = {
    "grpc.max_send_message_length": maxBytes,
    "grpc.max_receive_message_length": maxBytes,
    // channelz (grpc-js's call tracing for its admin service) is on by default and costs every
    // call some bookkeeping; this SDK serves no channelz
    "grpc.enable_channelz": 0,
    ...options.channelOptions,
  };
  return new Client(new GrpcTransport(endpoint.address, endpoint.tls, key, options.caFile, timeoutMs, channelOptions), url);
}

export { statusName };
