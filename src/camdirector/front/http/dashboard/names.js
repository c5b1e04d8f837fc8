// Players as people see them: the selected session's roster (GET /v1/sessions/{id}: id,
// display_name, team, team_name in target order) by id, and the id where a player has no name.
// A name is a game's text, untrusted: every module writes it with textContent, never as HTML.
import { state } from "./state.js";

export function showRoster(roster) {
  state.roster = new Map(roster.map((p) => [p.id, p]));
  // The director's reasons name players by id ("on the move: p01, ..."): a whole id in them, not
  // part of a longer word, is shown as its name. Longest first, so that "p1" never eats "p10".
  const named = roster.filter((p) => p.display_name).map((p) => p.id.replace(/[.*+?^${}()|[\]\\]/g, "\\$&"));
  named.sort((a, b) => b.length - a.length);
  state.rosterPattern = named.length ? new RegExp(`(?<![\\w-])(?:${named.join("|")})(?![\\w-])`, "gu") : null;
  const list = document.getElementById("players");
  list.replaceChildren(...roster.map((p) => {
    const li = document.createElement("li");
    li.textContent = p.team_name ? `${playerName(p.id)} (${p.team_name})` : playerName(p.id);
    li.title = p.id;   // the id the frames, events and takes use
    return li;
  }));
}

export function playerName(id) {
  const player = state.roster.get(id);
  return player && player.display_name ? player.display_name : id;
}

export function playerNames(ids) {
  return ids.map(playerName).join(", ");
}

export function withNames(text) {   // a text that names players by id (a shot's reason), with their names
  return state.rosterPattern ? text.replace(state.rosterPattern, playerName) : text;
}
