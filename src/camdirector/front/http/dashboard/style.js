// The selected session's style: shown as the server reports it (protobuf JSON), edited in the form
// (each rig's own fields) and applied live with PUT /v1/sessions/{id}/style. The match director's
// options are the server's registry of directors, GET /v1/match-directors (registry order), and
// the form sends the one chosen by name (`matchDirectorName`). A style that names none shows the
// director whose `wire` is its `matchDirector` enum, or else the default, as the server reads it.
import { api, sessionPath } from "./api.js";
import { state } from "./state.js";

const RIG_FIELDS = { RIG_TORIC: "toric-fields", RIG_TRACKS: "tracks-fields", RIG_MATCH: "match-fields" };
const TORIC_NUMBERS = ["preferredPhiDeg", "preferredThetaRatio", "responseTimeS", "maxSpeedMS"];   // the form edits
const MATCH_NUMBERS = ["minShotS", "maxShotS"];          // a match's style numbers the form edits
const DEFAULT_DIRECTOR = "planned";                      // the director of a style that names none

// Asked for with the polls until it came: the form's director options, filled once per page.
export async function loadDirectors() {
  if (state.directors) return;
  const { directors } = await api("/v1/match-directors");
  state.directors = directors;
  const select = document.getElementById("style-form").matchDirectorName;
  select.replaceChildren(...directors.map((d) => new Option(d.label, d.name)));
  select.value = directorName(state.currentStyle);   // a style shown before its options came
}

function directorName(style) {
  if (style.matchDirectorName) return style.matchDirectorName;
  const wired = (state.directors || []).find((d) => d.wire !== null && d.wire === style.matchDirector);
  return wired ? wired.name : DEFAULT_DIRECTOR;
}

export function showStyle(style) {
  state.currentStyle = style;
  const text = JSON.stringify(style, null, 1);
  document.getElementById("style-json").textContent = text;
  if (state.styleSentBySession[state.selected] === text) return;   // do not overwrite what the user is editing
  state.styleSentBySession[state.selected] = text;
  const form = document.getElementById("style-form");
  // Each rig's own fields: the others would be refused (or, for the Toric fields on a match, mean nothing).
  const rig = RIG_FIELDS[style.rig] ? style.rig : "RIG_TORIC";
  for (const [key, fieldset] of Object.entries(RIG_FIELDS)) {
    document.getElementById(fieldset).hidden = document.getElementById(fieldset).disabled = key !== rig;
  }
  form.visibility.value = style.visibility && style.visibility !== "VISIBILITY_MODE_UNSPECIFIED"
    ? style.visibility : "FRAMING_ONLY";
  for (const name of TORIC_NUMBERS) form[name].value = style[name] ?? "";
  form.shotSize.value = style.shotSize || "SHOT_SIZE_LONG";
  form.movement.value = style.movement || "MOVEMENT_DYNAMIC_WITH_CUTS";
  form.matchDirectorName.value = directorName(style);
  for (const name of MATCH_NUMBERS) form[name].value = style[name] ?? "";
}

// The form's submit: true once the server took the style (the session is then to be shown anew).
export async function applyStyle(event) {
  event.preventDefault();
  const form = event.target;
  const style = { ...state.currentStyle };   // PUT replaces the whole style: start from the session's
  if (style.rig === "RIG_TRACKS") {
    style.shotSize = form.shotSize.value;
    style.movement = form.movement.value;
  } else if (style.rig === "RIG_MATCH") {
    style.matchDirectorName = form.matchDirectorName.value;
    delete style.matchDirector;   // the name says which director; the enum would be a second answer
    setNumbers(style, form, MATCH_NUMBERS);
  } else {
    style.visibility = form.visibility.value;
    setNumbers(style, form, TORIC_NUMBERS);
  }
  const result = document.getElementById("style-result");
  try {
    await api(`${sessionPath(state.selected)}/style`, {
      method: "PUT", headers: { "Content-Type": "application/json" }, body: JSON.stringify(style),
    });
    result.className = "ok";
    result.textContent = "applied";
    delete state.styleSentBySession[state.selected];
    return true;
  } catch (error) {
    result.className = "error";
    result.textContent = error.message;
    return false;
  }
}

function setNumbers(style, form, names) {   // an empty field leaves the number to the server's default
  for (const name of names) {
    if (form[name].value === "") delete style[name];
    else style[name] = Number(form[name].value);
  }
}
