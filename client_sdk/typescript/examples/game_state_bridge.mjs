// A small HTTP bridge from a game's JSON state feed to a RIG_MATCH session: each POSTed state
// becomes one frame (players' transforms, kill events) and is answered with the program camera
// and shot as JSON. The JSON it takes and gives is in docs/engines.md ("A game-state bridge").
//
//   node examples/game_state_bridge.mjs URL [--port 8787] [--host 127.0.0.1] [--delay-s 0] [--level LEVEL_ID]
//
// URL: grpc://, grpcs:// or tcp:// (ZeroMQ). The key: CAMDIRECTOR_KEY; TLS: CAMDIRECTOR_CA (a PEM
// file); ZeroMQ's CURVE: CAMDIRECTOR_ZMQ_SERVER_KEY. Prints {"listening": "http://HOST:PORT"} once
// it listens (--port 0: a free port). The session is made at the first POST /state, with the
// players it lists (a match's players are known from its start); POST /reset closes it, so that
// the next state starts a new one.
import { createServer } from "node:http";
import { pathToFileURL } from "node:url";
import { parseArgs } from "node:util";
import { connect, DirectorError, pb } from "../dist/index.js";

const HTTP_STATUS = { INVALID_ARGUMENT: 400, NOT_FOUND: 404, FAILED_PRECONDITION: 409, OUT_OF_RANGE: 400 };
const CAPSULE = { source: { case: "primitive", value: { shape: { case: "capsule", value: { radius: 0.3, height: 1.8 } } } } };

/** A bad feed, answered 400 with `message`. */
class FeedError extends Error {}

const isNumber = (v) => typeof v === "number" && Number.isFinite(v);
function vector(value, where) {
  if (!Array.isArray(value) || value.length !== 3 || !value.every(isNumber)) throw new FeedError(`${where} must be [x, y, z], finite numbers`);
  return { x: value[0], y: value[1], z: value[2] };
}

/** A player's transform: its position, turned by yaw_deg about +Y (0 facing +Z, 90 facing +X).
 * The body does not pitch: pitch_deg is read for feeds that send it, and not used. */
function transform(player, where) {
  const yaw = (player.yaw_deg ?? 0) * Math.PI / 180;
  if (!isNumber(yaw) || (player.pitch_deg !== undefined && !isNumber(player.pitch_deg))) {
    throw new FeedError(`${where}.yaw_deg and pitch_deg must be finite numbers`);
  }
  return { position: vector(player.position, `${where}.position`), rotation: { x: 0, y: Math.sin(yaw / 2), z: 0, w: Math.cos(yaw / 2) } };
}

/** The feed's state checked: { timeS, players, events }. */
function parseState(state) {
  if (typeof state !== "object" || state === null || Array.isArray(state)) throw new FeedError("the body must be a JSON object");
  if (!isNumber(state.time_s)) throw new FeedError("time_s must be a finite number (seconds)");
  if (!Array.isArray(state.players) || state.players.length === 0) throw new FeedError("players must be a non-empty array");
  const players = state.players.map((p, i) => {
    if (typeof p !== "object" || p === null || typeof p.id !== "string" || p.id === "") throw new FeedError(`players[${i}].id must be a non-empty string`);
    if (p.team !== undefined && !(Number.isInteger(p.team) && p.team >= 0)) throw new FeedError(`players[${i}].team must be an integer >= 0`);
    return { id: p.id, team: p.team ?? 0, alive: p.alive !== false, transform: transform(p, `players[${i}]`) };
  });
  const events = (state.events ?? []).map((e, i) => {
    if (typeof e !== "object" || e === null || e.kind !== "kill") throw new FeedError(`events[${i}].kind must be "kill"`);
    if (typeof e.attacker !== "string" || typeof e.victim !== "string") throw new FeedError(`events[${i}] needs attacker and victim ids`);
    return { kind: pb.EventKind.EVENT_KILL, actorId: e.attacker, otherActorId: e.victim, label: String(e.weapon ?? "") };
  });
  return { timeS: state.time_s, players, events };
}

const pose = (p) => p && { position: [p.position.x, p.position.y, p.position.z], rotation: [p.rotation.x, p.rotation.y, p.rotation.z, p.rotation.w], vertical_fov_deg: p.verticalFovDeg };
const shot = (s) => ({ subjects: [...(s?.subjectIds ?? [])], kind: pb.ShotKind[s?.kind ?? 0], reason: s?.reason ?? "", held: s?.held ?? false });

/** A CameraUpdate as the bridge's JSON answer. */
function answer(u) {
  return {
    frame: Number(u.frame), time_s: u.timeS, buffering: u.buffering, stale: u.stale, cut: u.cut,
    camera: u.buffering ? null : pose(u.pose), shot: shot(u.shot),
    candidates: u.candidates.map((c) => ({ ...shot(c.shot), score: c.score })),
  };
}

/** The bridge: an HTTP server feeding one session at a time of `client`. States are taken one after
 * another, in the order they arrive (a frame's number is its place in the feed). */
export function bridge(client, { delayS = 0, levelId = "" } = {}) {
  let session, frame = 0, queue = Promise.resolve();

  async function onState(body) {
    const state = parseState(body);
    if (session === undefined) {
      session = await client.createSession({
        targets: state.players.map((p) => ({ id: p.id, team: p.team, mesh: CAPSULE, aimOffset: { y: 0.6 }, transform: p.transform })),
        style: { rig: pb.Rig.MATCH }, delayS, levelId,
      });
      frame = 0;
    }
    // a dead player's body stays where the server last had it; the kill event says it died
    const states = state.players.filter((p) => p.alive).map((p) => ({ id: p.id, transform: p.transform }));
    return answer(await session.frame(++frame, state.timeS, { states, events: state.events }));
  }

  async function onReset() {
    const closed = session;
    session = undefined;
    return { frames: closed === undefined ? 0 : Number(await closed.close()) };
  }

  const server = createServer((request, response) => {
    const reply = (status, body) => {
      response.writeHead(status, { "content-type": "application/json" });
      response.end(JSON.stringify(body));
    };
    const route = `${request.method} ${request.url}`;
    if (route !== "POST /state" && route !== "POST /reset") return reply(404, { error: `no route ${route}: POST /state or POST /reset` });
    const chunks = [];
    request.on("data", (chunk) => chunks.push(chunk));
    request.on("end", () => {
      queue = queue.then(async () => {
        try {
          if (route === "POST /reset") return reply(200, await onReset());
          let body;
          try { body = JSON.parse(Buffer.concat(chunks).toString("utf8")); } catch (error) { throw new FeedError(`the body is not JSON: ${error.message}`); }
          reply(200, await onState(body));
        } catch (error) {
          if (error instanceof FeedError) return reply(400, { error: error.message });
          if (error instanceof DirectorError) return reply(HTTP_STATUS[error.code] ?? 502, { error: error.message, code: error.code });
          reply(500, { error: String(error) });
        }
      });
    });
  });
  server.reset = onReset; // closes the session, if any: for a caller shutting the bridge down
  return server;
}

if (import.meta.url === pathToFileURL(process.argv[1] ?? "").href) {
  const { positionals, values } = parseArgs({
    allowPositionals: true,
    options: { port: { type: "string", default: "8787" }, host: { type: "string", default: "127.0.0.1" },
               "delay-s": { type: "string", default: "0" }, level: { type: "string", default: "" } },
  });
  const url = positionals[0] ?? "grpc://127.0.0.1:50051";
  const client = connect(url, { caFile: process.env.CAMDIRECTOR_CA || undefined, zmqServerKey: process.env.CAMDIRECTOR_ZMQ_SERVER_KEY || undefined });
  const server = bridge(client, { delayS: Number(values["delay-s"]), levelId: values.level });
  server.listen(Number(values.port), values.host, () => {
    const { address, port } = server.address();
    console.log(JSON.stringify({ listening: `http://${address}:${port}` }));
  });
  const stop = () => server.close(() => server.reset().catch(() => undefined).finally(() => client.close()));
  process.on("SIGINT", stop);
  process.on("SIGTERM", stop);
}
