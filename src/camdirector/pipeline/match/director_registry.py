"""The one registry of match directors: name -> entry (its name, a one-line label, the wire enum
value of a built-in, and the factory that makes it for a session), in the order they were
registered: ours, then the baselines, then the plugins' directors.

Everything that offers or resolves a director reads it: the codec (a Style's `match_director`
enum or `match_director_name`, worker/codec.py), the rig (rig.py makes the style's director from
its entry), the evaluation (`camdirector eval-match --director`, evaluation/match/) and the
dashboard (`GET /v1/match-directors`, front/http/routes/directors.py). Adding a director is one
module implementing `MatchDirector` (director_contract.py) and one `register(...)`: a built-in's
entry is below; a studio's own director is a module of its own that calls `register` when it is
imported, named in the server's `plugins` (server_settings.py: every process that may run a
session imports it at start, infra/plugins.py). A registered name is never taken over: a second
registration of one name is refused.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass

from camdirector.pipeline.match.autotrack import AutotrackDirector
from camdirector.pipeline.match.director_contract import DirectorContext, MatchDirector
from camdirector.pipeline.match.hltv import HltvDirector
from camdirector.pipeline.match.planned import PlannedDirector


@dataclass(frozen=True)
class DirectorEntry:
    """A registered director."""

    name: str  # what a Style names it by: [a-z0-9_-]{1,64}
    label: str  # one line for a person choosing it (the dashboard)
    factory: Callable[[DirectorContext], MatchDirector]  # makes it for a session (director_contract.py)
    wire: str | None = None  # its camdirector.v1.MatchDirector value's name; None: by name only


_ENTRIES: dict[str, DirectorEntry] = {}
DEFAULT_DIRECTOR = "planned"  # a MATCH style that names none (MATCH_DIRECTOR_UNSPECIFIED)


def register(entry: DirectorEntry) -> DirectorEntry:
    """Adds a director; ValueError for a name that is taken or not [a-z0-9_-]{1,64}."""
    if not re.fullmatch(r"[a-z0-9_-]{1,64}", entry.name):
        raise ValueError(f"a match director's name is 1 to 64 lower case letters, digits, '_' and '-', got {entry.name!r}")
    if entry.name in _ENTRIES:
        raise ValueError(f"a match director named {entry.name!r} is already registered")
    _ENTRIES[entry.name] = entry
    return entry


def registered() -> list[DirectorEntry]:
    """Every registered director, in the order of registration."""
    return list(_ENTRIES.values())


def director_entry(name: str) -> DirectorEntry:
    """The entry of that name; KeyError naming the registered ones for another."""
    try:
        return _ENTRIES[name]
    except KeyError:
        raise KeyError(f"{name!r} is not a registered match director; the registered ones are {', '.join(_ENTRIES)}") from None


def director_by_wire(wire: str) -> DirectorEntry | None:
    """The built-in whose wire enum value is named `wire`; None for none."""
    return next((e for e in _ENTRIES.values() if e.wire == wire), None)


register(
    DirectorEntry("planned", "ours: interest, the delay's look-ahead plan, film rules", PlannedDirector, "MATCH_DIRECTOR_PLANNED")
)
register(
    DirectorEntry(
        "hltv",
        "the baseline: Valve's HLTV director's published rules",
        lambda c: HltvDirector(c.players, c.settings, c.lens, c.ray_scene, c.rng, c.delay_s, c.level_nodes_world),
        "MATCH_DIRECTOR_HLTV",
    )
)
register(
    DirectorEntry(
        "autotrack",
        "QuakeWorld casters' baseline: ezQuake's mvd_autotrack, the best player in first person",
        lambda c: AutotrackDirector(c.players, c.teams, c.lens, c.player_stats),
        "MATCH_DIRECTOR_AUTOTRACK",
    )
)
