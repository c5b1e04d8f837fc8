/**
 * What a session's calls go through, and its gRPC form (`grpc://`, `grpcs://`) on @grpc/grpc-js.
 * The ZeroMQ form is zmq_transport.ts. Both take requests already serialized and answer messages.
 */
import { readFileSync } from "node:fs";
import { inspect } from "node:util";
import * as grpc from "@grpc/grpc-js";
import { fromBinary, type DescMessage, type MessageShape } from "@bufbuild/protobuf";
import { CameraUpdateSchema, type CameraUpdate } from "./gen/camdirector/v1/director_pb.js";
import { DirectorError } from "./errors.js";
import { PROTOCOL, PROTOCOL_HEADER, ROUTE_HEADER } from "./wire.js";

const SERVICE = "/camdirector.v1.Director/";

/** A director server reached one way. Every call carries the session's route key (gRPC; ZeroMQ
 * talks to one node and needs none). */
export interface Transport {
  readonly closed: boolean;
  /** True: `stream` opens a StreamFrames call; false: a stream is one Frame request per update. */
  readonly streams: boolean;
  /** One request/reply RPC (`method`: "Frame", "CreateSession", ...) of the serialized `request`.
   * `frameTimeoutMs` (gRPC, a Frame): a shorter deadline, whose passing is a hung node (UNAVAILABLE). */
  unary<D extends DescMessage>(method: string, request: Uint8Array, response: D, route: string,
                               frameTimeoutMs?: number): Promise<MessageShape<D>>;
  /** A StreamFrames call; only where `streams`. */
  stream(route: string): grpc.ClientDuplexStream<Uint8Array, CameraUpdate>;
  /** `error` as a DirectorError (a grpc-js ServiceError's code and details). */
  error(error: unknown): DirectorError;
  close(): void;
}

const identity = (bytes: Uint8Array) => Buffer.from(bytes.buffer, bytes.byteOffset, bytes.byteLength);

/**
 * gRPC through grpc-js, bytes in, messages out. Unary calls go straight onto the channel
 * (`Channel.createCall`, as grpc-js's own `Client.makeUnaryRequest` does underneath) without the
 * Client's interceptor chain, its call event emitter and the stack trace it captures on every call
 * for errors: the SDK has no interceptors and makes its own errors, and that machinery was a
 * measured part of a unary Frame's client time (load_tests/ts_sdk_bench.py). StreamFrames keeps
 * the Client's duplex stream, which the retry and resume logic reads.
 */
export class GrpcTransport implements Transport {
  readonly streams = true;
  readonly #client: grpc.Client;
  readonly #channel: grpc.Channel;
  readonly #auth: string | undefined; // "Bearer KEY": kept out of inspect, errors and logs
  readonly #timeoutMs: number;
  readonly #tls: boolean;
  #metadata = new Map<string, grpc.Metadata>(); // by route: built once per session
  closed = false;

  constructor(address: string, tls: boolean, key: string | undefined, caFile: string | undefined, timeoutMs: number,
              options: grpc.ChannelOptions) {
    let credentials: grpc.ChannelCredentials;
    if (tls) {
      let roots: Buffer | null = null;
      if (caFile !== undefined) {
        try { roots = readFileSync(caFile); } catch (error) {
          throw new DirectorError("INVALID_ARGUMENT", `caFile ${JSON.stringify(caFile)} can not be read: ${(error as Error).message}`);
        }
      }
      credentials = grpc.credentials.createSsl(roots);
    } else {
      credentials = grpc.credentials.createInsecure();
    }
    this.#client = new grpc.Client(address, credentials, options);
    this.#channel = this.#client.getChannel() as grpc.Channel;
    this.#auth = key === undefined ? undefined : `Bearer ${key}`;
    this.#timeoutMs = timeoutMs;
    this.#tls = tls;
  }

  metadata(route: string): grpc.Metadata {
    const cached = this.#metadata.get(route);
    if (cached !== undefined) return cached;
    const md = new grpc.Metadata();
    md.set(ROUTE_HEADER, route);
    md.set(PROTOCOL_HEADER, String(PROTOCOL));
    if (this.#auth !== undefined) md.set("authorization", this.#auth);
    if (this.#metadata.size > 4096) this.#metadata.clear();
    this.#metadata.set(route, md);
    return md;
  }

  error(error: unknown): DirectorError {
    if (error instanceof DirectorError) return error;
    const e = error as grpc.ServiceError;
    if (typeof e?.code !== "number") return new DirectorError("UNKNOWN", String((error as Error)?.message ?? error));
    return this.#statusError(e.code, e.details || e.message);
  }

  #statusError(code: number, message: string): DirectorError {
    const hint = connectionHint(code, message, this.#tls);
    return new DirectorError(code, hint ? `${message} (${hint})` : message);
  }

  unary<D extends DescMessage>(method: string, request: Uint8Array, response: D, route: string,
                               frameTimeoutMs?: number): Promise<MessageShape<D>> {
    if (this.closed) return Promise.reject(new DirectorError("CANCELLED", "the client is closed"));
    const hung = frameTimeoutMs !== undefined && frameTimeoutMs < this.#timeoutMs;
    return new Promise((resolve, reject) => {
      const call = this.#channel.createCall(SERVICE + method, Date.now() + (hung ? frameTimeoutMs : this.#timeoutMs), null, null, null);
      let reply: Buffer | null = null;
      call.start(this.metadata(route), {
        onReceiveMetadata() {},
        onReceiveMessage(message: Buffer) { reply = message; },
        onReceiveStatus: (status) => {
          if (hung && status.code === grpc.status.DEADLINE_EXCEEDED) {
            return reject(new DirectorError("UNAVAILABLE",
              `the frame was not answered within ${frameTimeoutMs} ms (frameTimeoutMs): the node may be hung`));
          }
          if (status.code !== grpc.status.OK) return reject(this.#statusError(status.code, status.details));
          if (reply === null) return reject(new DirectorError("UNIMPLEMENTED", `no reply message to ${method}`));
          try { resolve(fromBinary(response, reply)); } catch (error) {
            reject(new DirectorError("INTERNAL", `a reply to ${method} that is not a ${response.typeName}: ${(error as Error).message}`));
          }
        },
      });
      call.startRead();
      call.sendMessageWithContext({}, identity(request));
      call.halfClose();
    });
  }

  stream(route: string): grpc.ClientDuplexStream<Uint8Array, CameraUpdate> {
    if (this.closed) throw new DirectorError("CANCELLED", "the client is closed");
    return this.#client.makeBidiStreamRequest(
      SERVICE + "StreamFrames", identity, (bytes: Buffer) => fromBinary(CameraUpdateSchema, bytes), this.metadata(route), {},
    );
  }

  close(): void {
    this.closed = true;
    this.#client.close();
  }

  [inspect.custom](): string {
    return `GrpcTransport(key=${this.#auth === undefined ? "none" : "set"}, tls=${this.#tls})`;
  }
}

/** A word on what to check when no connection could be made (TLS on one side only, an untrusted CA). */
function connectionHint(code: number, message: string, tls: boolean): string | undefined {
  if (code !== grpc.status.UNAVAILABLE) return undefined;
  const said = message.toLowerCase().replace(/_/g, " ");
  if (said.includes("connection refused") || said.includes("econnrefused")) return undefined;
  if (tls && (said.includes("certificate") || said.includes("self-signed") || said.includes("self signed"))) {
    return "the server's certificate is not signed by an authority this client trusts: give caFile, the PEM of the CA that signed it";
  }
  if (tls && (said.includes("handshake") || said.includes("wrong version number") || said.includes("ssl"))) {
    return "the TLS handshake failed: does the server serve TLS (--tls-cert)? grpc:// is plaintext";
  }
  if (!tls && (said.includes("protocol error") || said.includes("connection dropped") || said.includes("closed"))) {
    return "the server closed the connection: if it serves TLS, connect with grpcs://";
  }
  return undefined;
}
