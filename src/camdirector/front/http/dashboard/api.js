// Every request of the page. The login cookie goes with it (same origin: HttpOnly, no script here
// reads it); a request that changes anything carries the CSRF token the login gave (docs/security.md);
// a 401 (the key revoked, the login expired) goes to the handler the page set with onUnauthorized,
// which brings the login form back with the server's reason.
import { state } from "./state.js";

const SAFE_METHODS = ["GET", "HEAD", "OPTIONS"];   // the methods the server asks no CSRF token of (front/http/auth.py)

let unauthorized = () => {};

export function onUnauthorized(handler) {   // handler(detail): the server's reason for the 401
  unauthorized = handler;
}

export class ApiError extends Error {   // the server answered, not with 2xx: its status, and its own words in detail
  constructor(status, detail) {
    super(`${status}: ${detail}`);
    this.status = status;
    this.detail = detail;
  }
}

export async function send(path, options = {}) {
  const headers = new Headers(options.headers);
  const caller = state.caller;
  if (!SAFE_METHODS.includes((options.method || "GET").toUpperCase()) && caller && caller.csrf_token) {
    headers.set("X-CSRF-Token", caller.csrf_token);
  }
  const reply = await fetch(path, { ...options, headers, credentials: "same-origin" });
  if (reply.ok) return reply;
  const text = await reply.text();
  const body = text ? JSON.parse(text) : {};
  const detail = Array.isArray(body.detail)
    ? body.detail.map((d) => `${(d.loc || []).join(".")}: ${d.msg}`).join("; ")
    : body.detail || reply.statusText;
  if (reply.status === 401) unauthorized(detail);
  throw new ApiError(reply.status, detail);
}

export async function api(path, options = {}) {   // the reply's JSON body
  const text = await (await send(path, options)).text();
  return text ? JSON.parse(text) : {};
}

export function sessionPath(sessionId) {
  return `/v1/sessions/${encodeURIComponent(sessionId)}`;
}
