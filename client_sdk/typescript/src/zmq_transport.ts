/**
 * ZeroMQ (`tcp://host:port`) through the `zeromq` package (v6: libzmq 4.3 with CURVE, prebuilt in
 * the npm package), as the Python SDK's `_ZmqTransport` and envelope
 * (client_sdk/python/camdirector_client/client.py, wire.py: `zmq_request`, `zmq_reply_payload`,
 * `open_dealer`, `zmq_no_reply`; docs/protocol.md, "ZeroMQ transport"):
 *
 * - DEALER sockets, one request outstanding per socket, LINGER 0, send and receive timeouts of
 *   the client's timeout; up to IDLE_SOCKETS kept for reuse; a socket whose request timed out is
 *   closed, never reused, so a late reply is never taken for a later request's;
 * - a request is three frames, the RPC name (ASCII), the serialized request and `Bearer KEY`
 *   (two frames without a key); a reply two, the status code in ASCII decimal (`0` = OK) and the
 *   serialized response, or a UTF-8 error message;
 * - with `zmqServerKey` the sockets are CURVE clients of that server key, with a key pair made
 *   for this client.
 *
 * The native module is loaded at the first request, so that a program that only speaks gRPC
 * never loads it.
 */
import { existsSync, readFileSync } from "node:fs";
import { inspect } from "node:util";
import { fromBinary, type DescMessage, type MessageShape } from "@bufbuild/protobuf";
import type { Dealer } from "zeromq";
import { DirectorError, statusName } from "./errors.js";
import type { Transport } from "./transport.js";

type Zmq = typeof import("zeromq");

/** ZeroMQ sockets a client keeps open for reuse (the Python SDK's _IDLE_SOCKETS). */
const IDLE_SOCKETS = 8;
const CURVE_KEY_CHARS = 40; // a CURVE public key in Z85 text
const Z85 = "0123456789abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ.-:+=^!/*?&<>()[]{}@%$#";

let loaded: Promise<Zmq> | undefined;

function loadZmq(): Promise<Zmq> {
  loaded ??= import("zeromq").catch((error: Error) => {
    loaded = undefined;
    throw new DirectorError("FAILED_PRECONDITION", `tcp:// needs the zeromq package, which could not be loaded: ${error.message}`);
  });
  return loaded;
}

/**
 * The server's CURVE public key, Z85: `value` itself (40 characters of Z85 text), or read from the
 * certificate file it names (the server's `DIR/zmq/server.key`, whose `public-key = "..."` line
 * holds it). DirectorError(INVALID_ARGUMENT) when it is neither.
 */
export function curveServerKey(value: string): string {
  if (typeof value !== "string") throw new DirectorError("INVALID_ARGUMENT", "zmqServerKey must be a string");
  if (value.length === CURVE_KEY_CHARS && !existsSync(value)) {
    if ([...value].some((c) => !Z85.includes(c))) {
      throw new DirectorError("INVALID_ARGUMENT", "zmqServerKey is 40 characters long but not Z85 text");
    }
    return value;
  }
  let text: string;
  try { text = readFileSync(value, "utf8"); } catch {
    throw new DirectorError("INVALID_ARGUMENT", `zmqServerKey must be the server's CURVE public key (40 characters of Z85 text) or the path of its server.key file; ${JSON.stringify(value)} is neither`);
  }
  const key = /^\s*public-key\s*=\s*"([^"]*)"/m.exec(text)?.[1];
  if (key === undefined || key.length !== CURVE_KEY_CHARS || [...key].some((c) => !Z85.includes(c))) {
    throw new DirectorError("INVALID_ARGUMENT", `${JSON.stringify(value)} holds no CURVE public key (a public-key = "..." line of 40 Z85 characters)`);
  }
  return key;
}

/** The response bytes of a ZeroMQ reply; DirectorError for an error reply or a broken one. */
export function replyPayload(reply: readonly Buffer[]): Buffer {
  if (reply.length !== 2) throw new DirectorError("INTERNAL", `malformed reply: ${reply.length} frames, expected 2`);
  const [code, payload] = reply as [Buffer, Buffer];
  const text = code.toString("latin1");
  if (text === "0") return payload;
  let message = payload.toString("utf8");
  if (!/^\d{1,9}$/.test(text)) {
    throw new DirectorError("INTERNAL", `malformed status frame ${JSON.stringify(text.slice(0, 32))}: ${message}`);
  }
  const value = Number(text);
  if (statusName(value) === "UNKNOWN" && value !== 2) message = `status ${value}: ${message}`;
  throw new DirectorError(value, message);
}

export class ZmqTransport implements Transport {
  readonly streams = false;
  closed = false;
  readonly #endpoint: string;
  readonly #timeoutMs: number;
  readonly #auth: Buffer | undefined; // "Bearer KEY": kept out of inspect, errors and logs
  readonly #serverKey: string | undefined;
  #keys: { publicKey: string; secretKey: string } | undefined;
  readonly #idle: Dealer[] = [];
  readonly #open = new Set<Dealer>(); // every socket not closed yet, idle or busy: close() ends them all

  constructor(endpoint: string, key: string | undefined, serverKey: string | undefined, timeoutMs: number) {
    this.#endpoint = endpoint;
    this.#timeoutMs = timeoutMs;
    this.#auth = key === undefined ? undefined : Buffer.from(`Bearer ${key}`, "ascii");
    this.#serverKey = serverKey;
  }

  async #socket(): Promise<Dealer> {
    const idle = this.#idle.pop();
    if (idle !== undefined) return idle;
    const zmq = await loadZmq();
    let curve = {};
    if (this.#serverKey !== undefined) {
      const keys = this.#keys ??= zmq.curveKeyPair();
      curve = { curveServerKey: this.#serverKey, curvePublicKey: keys.publicKey, curveSecretKey: keys.secretKey };
    }
    let socket: Dealer;
    try {
      socket = new zmq.Dealer({ linger: 0, receiveTimeout: this.#timeoutMs, sendTimeout: this.#timeoutMs, ...curve });
    } catch (error) { // libzmq refused an option: a key that is Z85 text but no CURVE key
      throw new DirectorError("INVALID_ARGUMENT", `a ZeroMQ socket could not be made: ${(error as Error).message}`);
    }
    try { socket.connect(this.#endpoint); } catch (error) {
      socket.close();
      throw new DirectorError("INVALID_ARGUMENT", `can not connect to ${JSON.stringify(this.#endpoint)}: ${(error as Error).message}`);
    }
    this.#open.add(socket);
    return socket;
  }

  #close(socket: Dealer): void {
    this.#open.delete(socket);
    socket.close();
  }

  /** `frameTimeoutMs` (a Frame): a shorter wait for the reply, whose passing is a hung node
   * (UNAVAILABLE, tried again), as over gRPC. */
  async unary<D extends DescMessage>(method: string, request: Uint8Array, response: D, _route: string,
                                     frameTimeoutMs?: number): Promise<MessageShape<D>> {
    if (this.closed) throw new DirectorError("CANCELLED", "the client is closed");
    const socket = await this.#socket();
    const hung = frameTimeoutMs !== undefined && frameTimeoutMs < this.#timeoutMs;
    let reply: Buffer[];
    try {
      socket.receiveTimeout = hung ? frameTimeoutMs : this.#timeoutMs;
      const frames = [method, request];
      await socket.send(this.#auth === undefined ? frames : [...frames, this.#auth]);
      reply = await socket.receive();
    } catch (error) {
      this.#close(socket);
      if (this.closed) throw new DirectorError("CANCELLED", "the client is closed");
      if ((error as { code?: string }).code === "EAGAIN") {
        if (hung) {
          throw new DirectorError("UNAVAILABLE",
            `the frame was not answered within ${frameTimeoutMs} ms (frameTimeoutMs): the node may be hung`);
        }
        throw this.#noReply(method);
      }
      throw new DirectorError("UNAVAILABLE", `${method} to ${this.#endpoint} failed: ${(error as Error).message}`);
    }
    if (this.closed || this.#idle.length >= IDLE_SOCKETS) this.#close(socket);
    else this.#idle.push(socket);
    const payload = replyPayload(reply);
    try { return fromBinary(response, payload); } catch (error) {
      throw new DirectorError("INTERNAL", `a reply to ${method} that is not a ${response.typeName}: ${(error as Error).message}`);
    }
  }

  /** DEADLINE_EXCEEDED for a request left unanswered. A CURVE server drops a client that does not
   * know its key (or a plaintext one) without a word, so the message says what to check. */
  #noReply(method: string): DirectorError {
    const hint = this.#serverKey !== undefined ? "is zmqServerKey the server's public key?"
      : "a server with authentication on answers only clients given its CURVE key (zmqServerKey)";
    return new DirectorError("DEADLINE_EXCEEDED", `no reply to ${method} from ${this.#endpoint} within ${this.#timeoutMs / 1000} s (${hint})`);
  }

  stream(): never {
    throw new DirectorError("UNIMPLEMENTED", "ZeroMQ has no StreamFrames: a stream is one Frame request per update");
  }

  error(error: unknown): DirectorError {
    return error instanceof DirectorError ? error : new DirectorError("UNKNOWN", String((error as Error)?.message ?? error));
  }

  close(): void {
    this.closed = true;
    this.#idle.length = 0;
    for (const socket of [...this.#open]) this.#close(socket);
  }

  [inspect.custom](): string {
    return `ZmqTransport(${JSON.stringify(this.#endpoint)}, key=${this.#auth === undefined ? "none" : "set"}, curve=${this.#serverKey !== undefined})`;
  }
}
