/**
 * The one error class of the SDK. Every failed call rejects with a DirectorError whose `code` is
 * the gRPC status name the server (or the client: a deadline, a closed client, a bad argument)
 * answered, e.g. "NOT_FOUND" for an unknown session, "INVALID_ARGUMENT" for bad input,
 * "DEADLINE_EXCEEDED" when no reply came within the client's timeout.
 */
import { status } from "@grpc/grpc-js";

/** gRPC status names, as the server's status codes are named (grpc-js's `status` enum). */
export type StatusName =
  | "OK" | "CANCELLED" | "UNKNOWN" | "INVALID_ARGUMENT" | "DEADLINE_EXCEEDED" | "NOT_FOUND"
  | "ALREADY_EXISTS" | "PERMISSION_DENIED" | "RESOURCE_EXHAUSTED" | "FAILED_PRECONDITION"
  | "ABORTED" | "OUT_OF_RANGE" | "UNIMPLEMENTED" | "INTERNAL" | "UNAVAILABLE" | "DATA_LOSS"
  | "UNAUTHENTICATED";

export class DirectorError extends Error {
  /** The gRPC status name, e.g. "NOT_FOUND". */
  readonly code: StatusName;
  /** The gRPC status number, e.g. 5 for NOT_FOUND. */
  readonly codeNumber: number;

  constructor(code: StatusName | number, message: string) {
    const name = typeof code === "number" ? statusName(code) : code;
    super(message);
    this.name = "DirectorError";
    this.code = name;
    this.codeNumber = typeof code === "number" ? code : (status as unknown as Record<string, number>)[name] ?? 2;
  }

  override toString(): string {
    return `${this.code}: ${this.message}`;
  }
}

/** The status name of a gRPC status number; "UNKNOWN" for a number that names none. */
export function statusName(code: number): StatusName {
  const name = (status as unknown as Record<number, string>)[code];
  return (typeof name === "string" ? name : "UNKNOWN") as StatusName;
}
