// What the dashboard's modules share, in one place: who is logged in, the selected session, and
// what the monitors, the candidates table and the style form show of it. Each module reads and
// writes these fields here; none keeps its own copy between polls.
export const state = {
  // The caller, as /v1/whoami or /v1/login describe it: { key_id, role, tenant, verbs, csrf_token }
  // (key_id and csrf_token null without authentication); null while nobody is logged in.
  caller: null,
  selected: null,             // the selected session id
  styleSentBySession: {},     // session id -> the style the form was last filled from (JSON text)
  currentStyle: {},           // the selected session's style, as the server reported it
  buffered: { session: null, frames: [], events: [] },   // the selected session's frames and game events seen
  roster: new Map(),          // the selected session's targets by id: { id, display_name, team, team_name } (names.js)
  rosterPattern: null,        // a RegExp of the named targets' ids, to show names in texts that use ids (names.js)
  candidatesShown: "",        // the candidate shots the table shows (JSON), rebuilt only when they change
  candidatesPictured: { frame: null, ms: 0 },   // the frame the candidate monitors last asked for, and when
  cutShown: null,             // the cut the before/after monitors show: "<session> <newest cut frame seen>"
  cutPictures: [],            // their object URLs, released when replaced
  topViews: {},               // session id -> its top view: { image, world } once fetched, { failedMs } after a failure
  directors: null,            // the server's match directors, /v1/match-directors, once fetched
};
