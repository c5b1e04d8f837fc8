"""QuakeWorld obituary lines ("X rides Y's rocket") read back into who killed whom with what.

The server's game mod prints one line per death to everyone (PRINT_MEDIUM). The table follows
QW-Group/ktx src/client.c, ClientObituary (the mod that recorded today's MVDs), cross-checked with
the fragfile of QW-Group/mvdparser src/fragfile.dat and vikpe/mvdparser src/qw/fragprint.rs.
Names are matched against the players present, longest first, so a name holding spaces or the
words of a message still parses.

Labels: a frag's label is the weapon ("rl", "lg", "tele", "stomp", ...); a suicide's is
"suicide:<how>" ("suicide" alone for the kill command); a death to the world is "world:<cause>";
a teamkill's is "teamkill:<weapon>" (or "teamkill"). A teamkill's line names only one side
(`Obituary.killer` or `.victim` is "" for the side it leaves out); the caller finds the other.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Obituary:
    """One death: killer and victim names ("" where the line does not say), the label (module
    docstring). A suicide or a death to the world has killer == victim."""

    killer: str
    victim: str
    label: str


# (victim suffix, label): "<victim><suffix>", the victim killed itself or the world killed it.
_SELF = (
    (" tries to put the pin back in", "suicide:gl"),
    (" discovers blast radius", "suicide:rl"),
    (" becomes bored with life", "suicide:rl"),
    (" somehow becomes bored with life", "suicide:?"),
    (" electrocutes himself", "suicide:discharge"),
    (" electrocutes herself", "suicide:discharge"),
    (" railcutes himself", "suicide:discharge"),
    (" railcutes herself", "suicide:discharge"),
    (" discharges into the slime", "suicide:discharge"),
    (" discharges into the lava", "suicide:discharge"),
    (" discharges into the water", "suicide:discharge"),
    (" heats up the water", "suicide:discharge"),
    (" suicides", "suicide"),
    (" was squished", "world:squish"),
    (" sleeps with the fishes", "world:drown"),
    (" sucks it down", "world:drown"),
    (" gulped a load of slime", "world:slime"),
    (" can't exist on slime alone", "world:slime"),
    (" burst into flames", "world:lava"),
    (" turned into hot slag", "world:lava"),
    (" visits the Volcano God", "world:lava"),
    (" cratered", "world:fall"),
    (" fell to his death", "world:fall"),
    (" fell to her death", "world:fall"),
    (" blew up", "world:explobox"),
    (" was spiked", "world:trap"),
    (" was zapped", "world:laser"),
    (" ate a lavaball", "world:fireball"),
    (" tried to leave", "world:changelevel"),
    (" died", "world:hurt"),
    (" couldn't resist the shiny spawn point", "world:spawn"),
    (" got too close to the baby factory", "world:spawn"),
    (" was fragged by poor life choices", "world:spawn"),
)
# (prefix, suffix, label): "<prefix><victim><suffix>", a death the victim caused itself.
_SELF_WRAPPED = (("Satan's power deflects ", "'s telefrag", "suicide:tele"),)
# (middle, end, label): "<victim><middle><killer><end>".
_VICTIM_FIRST = (
    (" was telefragged by ", "'s Satan's power", "tele"),
    (" was telefragged by ", "", "tele"),
    (" was literally stomped into particles by ", "!", "stomp"),
    (" softens ", "'s fall", "stomp"),
    (" tried to catch ", "", "stomp"),
    (" was jumped by ", "", "stomp"),
    (" was crushed by ", "", "stomp"),
    (" was body pierced by ", "", "ng"),
    (" was nailed by ", "", "ng"),
    (" was punctured by ", "", "sng"),
    (" was perforated by ", "", "sng"),
    (" was ventilated by ", "", "sng"),
    (" was straw-cuttered by ", "", "sng"),
    (" eats ", "'s pineapple", "gl"),
    (" was gibbed by ", "'s grenade", "gl"),
    (" was gibbed by ", "'s rocket", "rl"),
    (" rides ", "'s rocket", "rl"),
    (" was brutalized by ", "'s quad rocket", "rl"),
    (" was smeared by ", "'s quad rocket", "rl"),
    (" was axed to pieces by ", "!", "axe"),
    (" was ax-murdered by ", "", "axe"),
    (" was hooked by ", "", "hook"),
    (" chewed on ", "'s boomstick", "sg"),
    (" was instagibbed by ", "", "sg"),
    (" was lead poisoned by ", "", "sg"),
    (" ate 8 loads of ", "'s buckshot", "ssg"),
    (" ate 2 loads of ", "'s buckshot", "ssg"),
    (" gets a natural disaster from ", "", "lg"),
    (" accepts ", "'s shaft", "lg"),
    (" drains ", "'s batteries", "discharge"),
    (" accepts ", "'s discharge", "discharge"),
    (" was railed by ", "", "rail"),
    (" killed by ", " ?", "?"),
)
# (middle, end, label): "<killer><middle><victim><end>".
_KILLER_FIRST = (
    (" squishes ", "", "squish"),
    (" stomps ", "", "stomp"),
    (" rips ", " a new one", "rl"),
)
# (suffix, label): "<victim><suffix>", a teammate killed the victim.
_TEAMKILLED = (
    (" was telefragged by his teammate", "teamkill:tele"),
    (" was telefragged by her teammate", "teamkill:tele"),
    (" was jumped by his teammate", "teamkill:stomp"),
    (" was jumped by her teammate", "teamkill:stomp"),
    (" was crushed by his teammate", "teamkill:stomp"),
    (" was crushed by her teammate", "teamkill:stomp"),
)
# (suffix, label): "<killer><suffix>", the killer killed a teammate.
_TEAMKILLS = (
    (" squished a teammate", "teamkill:squish"),
    (" checks his glasses", "teamkill"),
    (" checks her glasses", "teamkill"),
    (" loses another friend", "teamkill"),
    (" gets a frag for the other team", "teamkill"),
    (" mows down a teammate", "teamkill"),
)


def parse_obituary(line: str, names: list[str]) -> Obituary | None:
    """The death a printed line (no newline) reports, or None if it reports none of `names`'s deaths.

    names: the players present (readable text, as the line). A line naming both sides must name
    two of them; a line fitting several patterns takes the first in the module's table order
    (teamkills before frags: " was crushed by his teammate" is not a frag by "his teammate")."""
    by_length = sorted(set(names), key=len, reverse=True)
    for suffix, label in _TEAMKILLED:
        if line.endswith(suffix) and line[: -len(suffix)] in names:
            return Obituary("", line[: -len(suffix)], label)
    for suffix, label in _TEAMKILLS:
        if line.endswith(suffix) and line[: -len(suffix)] in names:
            return Obituary(line[: -len(suffix)], "", label)
    for suffix, label in _SELF:
        if line.endswith(suffix) and line[: -len(suffix)] in names:
            return Obituary(line[: -len(suffix)], line[: -len(suffix)], label)
    for prefix, suffix, label in _SELF_WRAPPED:
        if line.startswith(prefix) and line.endswith(suffix) and line[len(prefix) : -len(suffix)] in names:
            victim = line[len(prefix) : -len(suffix)]
            return Obituary(victim, victim, label)
    for first_is_victim, table in ((True, _VICTIM_FIRST), (False, _KILLER_FIRST)):
        for middle, end, label in table:
            pair = _two_names(line, middle, end, by_length)
            if pair:
                return Obituary(pair[1], pair[0], label) if first_is_victim else Obituary(pair[0], pair[1], label)
    return None


def _two_names(line: str, middle: str, end: str, by_length: list[str]) -> tuple[str, str] | None:
    """(first, second) if line is "<first><middle><second><end>" with both among the names."""
    if not line.endswith(end):
        return None
    body = line[: len(line) - len(end)]
    for first in by_length:
        if body.startswith(first + middle) and body[len(first) + len(middle) :] in by_length:
            return first, body[len(first) + len(middle) :]
    return None
