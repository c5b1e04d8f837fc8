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
 *   node was lost; a balancer resetting the stream of a node that died), or over gRPC a frame left
 *   unanswered for `retry.frameTimeoutMs` (a hung node), is tried again with the same session id,
 *   after jittered waits from 100 ms doubling to 1 s, until `retry.retryWindowMs` (30 s) has
 *   passed since the first failure (RetryPolicy); an answer starts the count again; a stream is
 *   opened again from its first unanswered update; UNAUTHENTICATED and PERMISSION_DENIED are
 *   never tried again;
 * - every FrameUpdate carries answered_frame (the newest answer the session had, never past the
 *   update sent before it); a DATA_LOSS "resend from K" (a node restored the session from a
 *   checkpoint that was behind) sends the kept updates from frame K again, in order, their answers
 *   not given twice; K no longer kept: that DATA_LOSS is thrown;
 * - unary calls have a deadline (timeoutMs; a unary Frame the shorter frameTimeoutMs); StreamFrames
 *   has none; over ZeroMQ a stream is one Frame request per update, each with the deadline;
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
  Backoff, DEFAULT_MAX_MESSAGE_BYTES, DEFAULT_RETRY, DEFAULT_TIMEOUT_MS, EncodedFrame, FrameDeadlines, PROTOCOL, RETRYABLE,
  SentHistory, encodeFrameUpdate, frameUpdate, newRouteKey, parseUrl, resendFrom, resolveKey, retryChannelOptions,
  retryPolicy, sleep, withAnsweredFrame, type FrameOptions, type RetryPolicy, type Sent,
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
  /** More grpc-js channel options; they override the ones above and the retry policy's. */
  channelOptions?: grpc.ChannelOptions;
  /** How failed calls are tried again, how long a frame may go unanswered, how many sent updates
   * are kept for a DATA_LOSS resend; settings left out take DEFAULT_RETRY's (see RetryPolicy). */
  retry?: Partial<RetryPolicy>;
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
 * unanswered updates again (after DATA_LOSS, the session's kept updates from the frame asked for),
 * then goes on with the caller's. Updates read from the caller's iterator are kept in the session's
 * history and join one queue (read, not yet answered), one read under way at a time whichever call
 * asked for it, so an update read as a call ends goes to the next call, never lost. */
class Resumable {
  readonly #source: AsyncIterator<StreamInput> | Iterator<StreamInput>;
  #pull: Promise<void> | undefined;
  #queue: Sent[] = []; // #queue[i] is update number #base + i
  #base = 0;
  /** The sequence number of the newest update this stream read. */
  lastSeq = 0;
  error: unknown = undefined;
  failed = false;
  done = false;

  constructor(updates: AsyncIterable<StreamInput> | Iterable<StreamInput>, private readonly sessionId: string,
              private readonly history: SentHistory) {
    this.#source = Symbol.asyncIterator in updates
      ? (updates as AsyncIterable<StreamInput>)[Symbol.asyncIterator]()
      : (updates as Iterable<StreamInput>)[Symbol.iterator]();
  }

  /** Number of the oldest unanswered update: where a new call starts. */
  get first(): number { return this.#base; }

  /** Update number `i` (from `first` on), reading the caller's iterator as needed; undefined at its end. */
  async get(i: number): Promise<Sent | undefined> {
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
      else {
        const sent = this.history.add(encodeInput(result.value, this.sessionId));
        this.lastSeq = sent.seq;
        this.#queue.push(sent);
      }
    } catch (error) {
      this.error = error;
      this.failed = true;
    }
  }

  /** The oldest unanswered update was answered: it, taken off the queue. */
  answered(): Sent {
    this.#base++;
    return this.#queue.shift()!;
  }

  /** After a DATA_LOSS: `resend` (the kept updates from the frame asked for) are the next call's first. */
  resend(resend: Sent[]): void {
    this.#queue = resend;
  }

  /** The stream is over: the caller's iterator is told (not waited for: it may be in a read). */
  close(): void {
    const source = this.#source;
    if (!this.done && !this.failed && typeof source.return === "function") {
      Promise.resolve().then(() => source.return!()).catch(() => undefined);
    }
  }
}

/** One director session. Calls answered UNAVAILABLE or CANCELLED, frames left unanswered and
 * DATA_LOSS resends are tried again (module comment). */
export class Session {
  /** Calls and streams tried again (UNAVAILABLE, CANCELLED, an unanswered frame, DATA_LOSS). */
  retries = 0;
  /** The frame of the newest answer given to the application. */
  answeredFrame = 0n;
  #answeredSeq = 0; // the SentHistory sequence number of that answer's update
  /** The updates this session sent, kept for a DATA_LOSS resend. */
  readonly history: SentHistory;
  #closedFrames: bigint | undefined;

  constructor(private readonly transport: Transport, readonly id: string, readonly recordingPath: string,
              /** The x-camdirector-route key of every call of this session. */ readonly route: string,
              readonly retry: RetryPolicy = DEFAULT_RETRY) {
    this.history = new SentHistory(retry.resendHistoryFrames);
  }

  /** What JSON.stringify shows of a session: its ids and counts (frame numbers are bigints, which
   * JSON cannot write, and the kept updates are the application's data, not the session's). */
  toJSON(): object {
    return { id: this.id, recordingPath: this.recordingPath, route: this.route, retries: this.retries,
             answeredFrame: this.answeredFrame.toString() };
  }

  /** The wait before the next try after `error` and the backoff of the call's tries (`backoff`, or
   * one started now, at the first failure), the retry counted; throws `error` when it is neither
   * RETRYABLE nor a DATA_LOSS to resend, the window is spent, or the client is closed. */
  #retryAfter(error: DirectorError, backoff: Backoff | undefined): [number, Backoff] {
    const dataLoss = resendFrom(error) !== undefined;
    if ((!RETRYABLE.has(error.code) && !dataLoss) || this.transport.closed) throw error;
    backoff ??= new Backoff(this.retry);
    const delay = backoff.nextDelayMs(dataLoss);
    if (delay === undefined) throw error;
    this.retries++;
    return [delay, backoff];
  }

  /** `sent`'s bytes with the answered_frame it carries: the newest answer received, never past the
   * update sent before it (resent after DATA_LOSS, it says where the session stood when first sent). */
  #stamped(sent: Sent): Uint8Array {
    return withAnsweredFrame(sent.bytes, this.answeredFrame < sent.previousFrame ? this.answeredFrame : sent.previousFrame);
  }

  /** After `error`: the updates to send again from a DATA_LOSS's "resend from K", up to sequence
   * number `throughSeq` (undefined: all); undefined when it asks for none. Throws `error` when an
   * update from K on is no longer kept. */
  #resend(error: DirectorError, throughSeq?: number): Sent[] | undefined {
    const frame = resendFrom(error);
    if (frame === undefined) return undefined;
    const resend = this.history.since(frame, throughSeq, error);
    return resend.length > 0 ? resend : undefined;
  }

  /** Notes the answer to `sent`; false when the application already had it (a resend after
   * DATA_LOSS) and it is to be dropped. */
  #takeAnswer(sent: Sent, reply: CameraUpdate): boolean {
    if (sent.seq <= this.#answeredSeq) return false;
    this.#answeredSeq = sent.seq;
    this.answeredFrame = reply.frame;
    return true;
  }

  async #retrying<D extends DescMessage>(method: string, request: Uint8Array, response: D): Promise<MessageShape<D>> {
    let backoff: Backoff | undefined;
    for (;;) {
      try {
        return await this.transport.unary(method, request, response, this.route);
      } catch (caught) {
        const error = this.transport.error(caught);
        let delay: number;
        [delay, backoff] = this.#retryAfter(error, backoff); // throws when not to be tried again
        const resend = this.#resend(error);
        if (resend !== undefined) await this.#frameCall(resend[resend.length - 1]!, resend); // the frames the session lost first
        await sleep(delay);
      }
    }
  }

  /** A unary Frame of `sent` (after those `pending` before it), tried again as `#retrying`; after
   * DATA_LOSS the kept updates from the frame asked for are sent first, their answers dropped. */
  async #frameCall(sent: Sent, pending: Sent[] = [sent]): Promise<CameraUpdate> {
    let backoff: Backoff | undefined;
    for (;;) {
      let reply: CameraUpdate;
      try {
        reply = await this.transport.unary("Frame", this.#stamped(pending[0]!), CameraUpdateSchema, this.route,
          this.retry.frameTimeoutMs ?? undefined);
      } catch (caught) {
        const error = this.transport.error(caught);
        let delay: number;
        [delay, backoff] = this.#retryAfter(error, backoff); // throws when not to be tried again
        pending = this.#resend(error, sent.seq) ?? pending;
        await sleep(delay);
        continue;
      }
      backoff = undefined;
      if (pending.shift() === sent) {
        this.#takeAnswer(sent, reply);
        return reply;
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
    return this.#frameCall(this.history.add(encoded));
  }

  /** Sends a prebuilt FrameUpdate (its sessionId filled in when empty), or an EncodedFrame; its
   * answered_frame is set on the bytes sent, and they are kept for a DATA_LOSS resend. */
  send(update: StreamInput): Promise<CameraUpdate> {
    let encoded: EncodedFrame;
    try { encoded = encodeInput(update, this.id); } catch (error) { return Promise.reject(error); }
    return this.#frameCall(this.history.add(encoded));
  }

  /**
   * One CameraUpdate per update, in order, as they come: over gRPC one StreamFrames call, updates
   * written as the stream has room; over ZeroMQ one Frame request per update. `updates` may be sync
   * or async. Leaving the loop early (break, return) cancels the call. A call ended by UNAVAILABLE,
   * CANCELLED, a frame left unanswered for `retry.frameTimeoutMs` or a DATA_LOSS is opened again
   * with its unanswered updates first (module comment); each update is answered once, in order.
   */
  async *stream(updates: AsyncIterable<StreamInput> | Iterable<StreamInput>): AsyncGenerator<CameraUpdate, void, undefined> {
    const feed = new Resumable(updates, this.id, this.history);
    let backoff: Backoff | undefined;
    try {
      while (!this.transport.streams) { // ZeroMQ: one Frame request per update, each tried again as `frame`
        const sent = await feed.get(feed.first);
        if (sent === undefined) {
          if (feed.failed) throw feed.error;
          return;
        }
        const reply = await this.#frameCall(sent);
        feed.answered();
        yield reply;
      }
      let alone = false;
      for (;;) {
        if (alone) {
          // After a break (but a DATA_LOSS, which names its resend), the oldest unanswered update
          // goes alone as a unary Frame first: HAProxy before 3.2 resets a stream right after the
          // node ended it while the client still sent, hiding the node's status (a DATA_LOSS
          // "resend from K", a revoked key) behind CANCELLED (haproxy/haproxy#1219;
          // docs/scaling.md); a unary call's status arrives whole.
          alone = false;
          const sent = await feed.get(feed.first);
          if (sent !== undefined) {
            const fresh = sent.seq > this.#answeredSeq; // not one a DATA_LOSS resend answered already
            const reply = await this.#frameCall(sent);
            feed.answered();
            if (fresh) yield reply;
          }
        }
        const call = this.transport.stream(this.route);
        let over = false; // this call ended: its writer stops
        const end = () => { over = true; };
        call.on("status", end);
        call.on("error", end);
        const frameTimeoutMs = this.retry.frameTimeoutMs;
        const deadlines = frameTimeoutMs === null ? undefined : new FrameDeadlines(frameTimeoutMs);
        const watch = deadlines === undefined ? undefined : watchFrames(call, deadlines);
        const writer = (async () => {
          for (let i = feed.first; ; i++) {
            const sent = await feed.get(i);
            if (over) return;
            if (sent === undefined) {
              if (feed.failed) call.cancel(); // the caller's iterator threw: raised below
              else call.end();
              return;
            }
            deadlines?.sent(sent.frame);
            if (!call.write(this.#stamped(sent))) await drained(call, () => over);
          }
        })();
        try {
          for await (const reply of call as AsyncIterable<CameraUpdate>) {
            deadlines?.answered();
            backoff = undefined; // answered again: a later loss gets a whole window anew
            if (this.#takeAnswer(feed.answered(), reply)) yield reply;
          }
          if (feed.failed) throw feed.error;
          return;
        } catch (caught) {
          if (feed.failed) throw feed.error; // the caller's iterator failed: grpc saw only a cancel
          if (caught instanceof DirectorError) throw caught;
          const error = deadlines?.expired ?? this.transport.error(caught); // expired: the watch cancelled it
          let delay: number;
          [delay, backoff] = this.#retryAfter(error, backoff); // throws when not to be tried again
          const resend = this.#resend(error, feed.lastSeq);
          if (resend !== undefined) feed.resend(resend);
          alone = resendFrom(error) === undefined;
          over = true;
          call.cancel();
          await sleep(delay);
        } finally {
          over = true;
          clearTimeout(watch?.timer);
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

/** Cancels `call` when a frame on it is left unanswered past its deadline (a hung node). Answers
 * the call has received that the application has not read yet count as answers: a slow reader is
 * not a hung node. The returned holder has the pending timer, for clearTimeout. */
function watchFrames(call: grpc.ClientDuplexStream<Uint8Array, CameraUpdate>, deadlines: FrameDeadlines): { timer?: NodeJS.Timeout } {
  const watch: { timer?: NodeJS.Timeout } = {};
  const check = () => {
    const waitMs = call.readableLength > 0 ? deadlines.timeoutMs : deadlines.waitMs();
    if (deadlines.expired !== undefined) call.cancel();
    else watch.timer = setTimeout(check, waitMs).unref();
  };
  watch.timer = setTimeout(check, deadlines.timeoutMs).unref();
  return watch;
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

  constructor(transport: Transport, readonly url: string, readonly retry: RetryPolicy = DEFAULT_RETRY) {
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
    return new Session(this.#transport, response.sessionId, response.recordingPath, route, this.retry);
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
  const retry = retryPolicy(options.retry);
  if (options.caFile !== undefined && !endpoint.tls) {
    const instead = endpoint.transport === "zmq" ? "ZeroMQ is encrypted with CURVE: give zmqServerKey" : "use grpcs://";
    throw new DirectorError("INVALID_ARGUMENT", `caFile is for grpcs:// URLs (gRPC over TLS); ${instead}`);
  }
  if (options.zmqServerKey !== undefined && endpoint.transport !== "zmq") {
    throw new DirectorError("INVALID_ARGUMENT", "zmqServerKey is for tcp:// URLs (ZeroMQ); gRPC is encrypted with TLS: use grpcs://");
  }
  if (endpoint.transport === "zmq") {
    const serverKey = options.zmqServerKey === undefined ? undefined : curveServerKey(options.zmqServerKey);
    return new Client(new ZmqTransport(endpoint.address, key, serverKey, timeoutMs), url, retry);
  }
  const maxBytes = options.maxMessageBytes ?? DEFAULT_MAX_MESSAGE_BYTES;
  if (!(maxBytes > 0)) throw new DirectorError("INVALID_ARGUMENT", `maxMessageBytes must be > 0, got ${maxBytes}`);
  const channelOptions: grpc.ChannelOptions = {
    "grpc.max_send_message_length": maxBytes,
    "grpc.max_receive_message_length": maxBytes,
    // channelz (grpc-js's call tracing for its admin service) is on by default and costs every
    // call some bookkeeping; this SDK serves no channelz
    "grpc.enable_channelz": 0,
    ...retryChannelOptions(retry),
    ...options.channelOptions,
  };
  return new Client(new GrpcTransport(endpoint.address, endpoint.tls, key, options.caFile, timeoutMs, channelOptions), url, retry);
}

export { statusName };
