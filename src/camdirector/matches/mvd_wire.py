"""The QuakeWorld MVD wire format read into per-player timelines: where each player was, where it
looked, its health, armor, items and frags over demo time, and who killed whom.

An MVD ("multi-view demo", recorded by the server) is a run of blocks: a byte of milliseconds since
the block before, a byte whose low 3 bits say whom the block is for (dem_all, dem_single and
dem_stats carry the player slot in the high 5 bits, dem_multiple a 32-bit slot mask after it,
dem_set two sequence longs and nothing else), then a little-endian long length and that many
bytes of server messages (svc_*). Framing as QW-Group/ezquake-source src/cl_demo.c,
CL_GetDemoMessage and CL_DemoReadDemRead (dem_multiple to no one is hidden data and skipped) and
vikpe/mvdparser src/qw/frame.rs; messages as ezquake src/cl_parse.c, CL_ParseServerMessage, with
CL_ParseServerData (FTE and MVD extension longs before the protocol version; FTE_PEXT_FLOATCOORDS
makes coordinates 4-byte floats and angles 16-bit), src/cl_ents.c CL_ParsePlayerinfo's MVD branch
(DF_* delta flags), CL_ParsePacketEntities and CL_ParseDelta (FTE entity extensions;
MVD_PEXT1_FLOATCOORDS makes entity coordinates floats), src/cl_tent.c CL_ParseTEnt; the constants
are QW-Group/qwprot src/protocol.h's. The writer is QW-Group/mvdsv src/sv_demo.c
(SV_MVDWritePacketsEx: one dem_all block of svc_playerinfo per server frame, positions already
interpolated to the frame's time; svc_setangle to a player when it teleports or respawns).

A player's stats reach the demo as svc_updatestat / svc_updatestatlong in dem_stats blocks for its
slot (STAT_HEALTH 0, STAT_ARMOR 4, STAT_ITEMS 15); frags as svc_updatefrags; deaths as the game
mod's obituary lines (matches/quakeworld_obituaries.py). Text is Quake's character set: the high
bit only colours a character, 0x12..0x1b are digits, 0x10/0x11 brackets (`quake_text`).

Anything that is not this format raises MvdError with the byte offset and what was wrong. A file
that does not begin as every MVD does, with a block of messages whose first is svc_serverdata (the
writer's SV_MVD_Record sends the connection's serverdata first), is "not an MVD demo" however its
bytes would read on: random bytes are no truncated demo.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from camdirector.matches.quakeworld_obituaries import parse_obituary

# Block targets (protocol.h dem_*).
DEM_CMD, DEM_READ, DEM_SET, DEM_MULTIPLE, DEM_SINGLE, DEM_STATS, DEM_ALL = range(7)
SVC_SERVERDATA = 11  # protocol.h svc_serverdata: every MVD's first message
# Protocol extension markers in svc_serverdata and the bits we honour.
PROTOCOL_VERSION_FTE = 0x58455446  # "FTEX"
PROTOCOL_VERSION_FTE2 = 0x32455446  # "FTE2"
PROTOCOL_VERSION_MVD1 = 0x3144564D  # "MVD1"
FTE_PEXT_TRANS = 0x00000008
FTE_PEXT_ENTITYDBL = 0x00002000
FTE_PEXT_FLOATCOORDS = 0x00008000
FTE_PEXT_COLOURMOD = 0x00080000
MVD_PEXT1_FLOATCOORDS = 1 << 0
# MVD playerinfo delta flags.
DF_ORIGIN, DF_ANGLES, DF_EFFECTS, DF_SKINNUM = 1, 1 << 3, 1 << 6, 1 << 7
DF_DEAD, DF_GIB, DF_WEAPONFRAME, DF_MODEL = 1 << 8, 1 << 9, 1 << 10, 1 << 11
# Entity delta bits.
U_ORIGIN1, U_ORIGIN2, U_ORIGIN3, U_ANGLE2 = 1 << 9, 1 << 10, 1 << 11, 1 << 12
U_FRAME, U_REMOVE, U_MOREBITS = 1 << 13, 1 << 14, 1 << 15
U_ANGLE1, U_ANGLE3, U_MODEL, U_COLORMAP, U_SKIN, U_EFFECTS = 1, 1 << 1, 1 << 2, 1 << 3, 1 << 4, 1 << 5
U_FTE_EVENMORE = 1 << 7
U_FTE_TRANS, U_FTE_MODELDBL, U_FTE_YETMORE, U_FTE_COLOURMOD = 1 << 1, 1 << 3, 1 << 7, 1 << 10
# Player stats kept, and their column in MvdDemo.stats (frags, from svc_updatefrags, is the last).
STAT_HEALTH, STAT_ARMOR, STAT_ITEMS = 0, 4, 15
STAT_COLUMN = {STAT_HEALTH: 0, STAT_ARMOR: 1, STAT_ITEMS: 2}
FRAGS_COLUMN = 3
PRINT_MEDIUM = 1
MAX_CLIENTS = 32
# Temp entities: (type -> extra fields before the position) per CL_ParseTEnt.
TE_BEAMS = {5, 6, 9}  # entity short, start and end positions
TE_COUNTED = {2, 12}  # gunshot, blood: a count byte, then the position
TE_POSITION_ONLY = {0, 1, 3, 4, 7, 8, 10, 11, 13}

_I16, _U16, _I32, _U32, _F32 = (struct.Struct(f) for f in ("<h", "<H", "<i", "<I", "<f"))
# svc_playerinfo: for each combination of its delta flags, (coordinates sent, other bytes sent).
_PLAYERINFO_MASK = 0x3F | DF_EFFECTS | DF_SKINNUM | DF_WEAPONFRAME | DF_MODEL
_PLAYERINFO_FIELDS = {
    flags: (
        bin(flags & 7).count("1"),
        2 * bin(flags & 0x38).count("1") + sum(bool(flags & f) for f in (DF_EFFECTS, DF_SKINNUM, DF_WEAPONFRAME, DF_MODEL)),
    )
    for flags in range(_PLAYERINFO_MASK + 1)
    if flags & ~_PLAYERINFO_MASK == 0
}
_QUAKE_LOW = "[]0123456789.<=>"  # characters 0x10..0x1f


class MvdError(ValueError):
    """A file that is not a readable MVD; `offset` is the byte where reading failed, `reason` what
    was wrong there."""

    def __init__(self, offset: int, message: str):
        super().__init__(f"offset {offset}: {message}")
        self.offset, self.reason = offset, message


def quake_text(raw: bytes) -> str:
    """Readable ASCII of Quake's character set: coloured (high-bit) characters as plain, 0x10..0x1f
    as "[]0123456789.<=>", other control characters as "."."""
    out = []
    for b in raw:
        c = b & 0x7F
        out.append(_QUAKE_LOW[c - 0x10] if 0x10 <= c < 0x20 else "." if c < 0x20 or c == 0x7F else chr(c))
    return "".join(out)


@dataclass(frozen=True)
class MvdPlayer:
    """A slot that played (not a spectator): its readable name and team string."""

    slot: int
    name: str
    team: str


@dataclass(frozen=True)
class MvdTrack:
    """One player's svc_playerinfo samples: time_s (n,) float64 non-decreasing, origin_units (n, 3)
    float64 Quake units, angles_deg (n, 3) float64 (pitch, yaw, roll) and jump (n,) bool: sample k
    came through a teleport or respawn (svc_setangle to the slot, or its DF_DEAD flag cleared), so
    nothing moved continuously from sample k - 1 to it."""

    time_s: np.ndarray
    origin_units: np.ndarray
    angles_deg: np.ndarray
    jump: np.ndarray
    dead: np.ndarray


@dataclass(frozen=True)
class MvdStats:
    """One player's stat changes: time_s (m,) float64 and values (m, 4) int64, the (health, armor,
    items, frags) from that time on; row 0 is at time 0 with what was known first."""

    time_s: np.ndarray
    values: np.ndarray


@dataclass(frozen=True)
class MvdDeath:
    """An obituary at time_s: killer and victim slots (-1 where the line leaves a teamkill's other
    side unsaid), and its label (quakeworld_obituaries.py)."""

    time_s: float
    killer: int
    victim: int
    label: str


@dataclass(frozen=True)
class MvdDemo:
    """What an MVD recorded: map (the .bsp's name, "dm2"), level_title (the map's full name),
    teamplay (serverinfo, 0 when absent), duration_s (the last block's time), the playing slots in
    slot order with their samples and stats, and the deaths in time order."""

    map_name: str
    level_title: str
    teamplay: int
    duration_s: float
    players: list[MvdPlayer]
    tracks: dict[int, MvdTrack]
    stats: dict[int, MvdStats]
    deaths: list[MvdDeath]


class _Short(Exception):
    """A block that data cuts short at offset: the demo's end (whole file), or bytes yet to come
    (live)."""

    def __init__(self, offset: int, message: str):
        super().__init__(message)
        self.offset = offset


def _need(data: bytes, pos: int, n: int, what: str) -> None:
    if len(data) - pos < n:
        raise _Short(pos, f"truncated {what} (needs {n} bytes, {len(data) - pos} left)")


class _Cursor:
    """Reads one block's messages between pos and end; `what` names the message for errors."""

    __slots__ = ("data", "pos", "end", "what", "coord_size", "entity_float")

    def __init__(self, data: bytes, coord_size: int, entity_float: bool):
        self.data, self.pos, self.end, self.what = data, 0, 0, ""
        self.coord_size, self.entity_float = coord_size, entity_float

    def need(self, n: int) -> int:
        pos = self.pos
        if pos + n > self.end:
            raise MvdError(pos, f"truncated {self.what} (needs {n} bytes, {self.end - pos} left)")
        self.pos = pos + n
        return pos

    def byte(self) -> int:
        return self.data[self.need(1)]

    def skip(self, n: int) -> None:
        self.need(n)

    def short(self) -> int:
        return _I16.unpack_from(self.data, self.need(2))[0]

    def ushort(self) -> int:
        return _U16.unpack_from(self.data, self.need(2))[0]

    def long(self) -> int:
        return _I32.unpack_from(self.data, self.need(4))[0]

    def ulong(self) -> int:
        return _U32.unpack_from(self.data, self.need(4))[0]

    def float32(self) -> float:
        return _F32.unpack_from(self.data, self.need(4))[0]

    def coord(self) -> float:
        if self.coord_size == 4:
            return self.float32()
        return self.short() / 8.0

    def entity_coord(self) -> float:
        return self.float32() if self.entity_float else self.coord()

    def angle(self) -> None:
        self.skip(2 if self.coord_size == 4 else 1)

    def angle16(self) -> float:
        return self.short() * (360.0 / 65536.0)

    def string(self) -> bytes:
        end = self.data.find(b"\0", self.pos, self.end)
        if end < 0:
            raise MvdError(self.pos, f"truncated {self.what} (string without its terminating 0)")
        raw = self.data[self.pos : end].replace(b"\xff", b"")  # 255 is dropped by every reader
        self.pos = end + 1
        return raw


def _info_pairs(raw: bytes) -> dict[str, bytes]:
    """A Quake info string "\\key\\value\\key\\value" as {key: raw value}."""
    parts = raw.split(b"\\")
    if parts and parts[0] == b"":
        parts = parts[1:]
    return {parts[i].decode("latin-1"): parts[i + 1] for i in range(0, len(parts) - 1, 2)}


# Messages whose body is a fixed number of bytes, skipped whole: type -> (name in errors, bytes).
FIXED_BODIES = {
    1: ("_nop", 0),
    7: ("_nq_time", 4),
    16: ("_stopsound", 2),
    24: ("_byte", 1),
    27: ("_nop", 0),
    28: ("_nop", 0),
    32: ("_byte", 1),
    33: ("_nop", 0),
    34: ("_nop", 0),
    35: ("_nop", 0),
    36: ("_byte_short", 3),
    37: ("_updateentertime", 5),
    39: ("_short", 2),
    44: ("_byte", 1),
    49: ("_float", 4),
    50: ("_float", 4),
    53: ("_byte_byte", 2),
    83: ("_qizmovoice", 34),
}


class _Reader:
    """The state of one pass over a demo (module docstring)."""

    def __init__(self, data: bytes):
        self.data = data
        self.cur = _Cursor(data, 2, False)
        self.time_ms = 0
        self.last_type, self.last_to = DEM_ALL, 0
        self.fte_ext = self.mvd_ext = 0
        self.saw_serverdata = False
        self.map_name = self.level_title = ""
        self.serverinfo: dict[str, bytes] = {}
        self.userinfo: dict[int, dict[str, bytes]] = {}
        self.ever_named: dict[int, tuple[str, str]] = {}  # slot -> last (name, team) while playing
        self.origin = [[0.0, 0.0, 0.0] for _ in range(MAX_CLIENTS)]
        self.angles = [[0.0, 0.0, 0.0] for _ in range(MAX_CLIENTS)]
        self.dead = [False] * MAX_CLIENTS
        self.fixangle = [False] * MAX_CLIENTS
        self.samples: dict[int, list[tuple]] = {}  # slot -> [(t, x, y, z, p, y, r, jump)]
        self.stat_now = [[0, 0, 0, 0] for _ in range(MAX_CLIENTS)]
        self.stat_changes: dict[int, list[tuple]] = {}  # slot -> [(t, h, a, i, f)]
        self.print_buffer = b""
        self.deaths: list[MvdDeath] = []
        self.handlers = {
            2: self._disconnect,
            3: self._updatestat,
            6: self._sound,
            8: self._print,
            9: self._stufftext,
            10: self._setangle,
            SVC_SERVERDATA: self._serverdata,
            12: self._lightstyle,
            14: self._updatefrags,
            19: self._damage,
            20: self._spawnstatic,
            21: self._delta_from_short,
            22: self._spawnbaseline,
            23: self._temp_entity,
            26: self._string,
            29: self._spawnstaticsound,
            30: self._intermission,
            31: self._string,
            38: self._updatestatlong,
            40: self._updateuserinfo,
            41: self._download,
            42: self._playerinfo,
            43: self._nails,
            45: self._modellist,
            46: self._soundlist,
            47: self._packetentities,
            48: self._deltapacketentities,
            51: self._setinfo,
            52: self._serverinfo,
            54: self._nails2,
            60: self._modellistshort,
            66: self._delta_from_short,
        }

    # ---------------------------------------------------------------- blocks

    def run(self) -> None:
        if not self.data:
            raise MvdError(0, "empty file")
        self._check_start()
        self.blocks(self.data, final=True)
        if not self.saw_serverdata:
            raise MvdError(0, "no svc_serverdata: not an MVD")

    def blocks(self, data: bytes, *, final: bool) -> int:
        """Decodes data's whole blocks in order; returns where the first one data does not hold
        whole begins (len(data) when none). final: data is all there is, so a block it cuts short
        is a truncated demo (MvdError) rather than one whose rest has not come yet."""
        n, pos = len(data), 0
        while pos < n:
            start = pos
            try:
                _need(data, pos, 2, "block header")
                time_ms = self.time_ms + data[pos]
                kind = data[pos + 1]
                pos += 2
                target, to = kind & 7, kind >> 3
                if target == DEM_SET:
                    _need(data, pos, 8, "dem_set block")
                    self.time_ms = time_ms
                    pos += 8
                    continue
                if target == DEM_CMD:
                    raise MvdError(pos - 1, "dem_cmd block: a client's .qwd demo, not a server's MVD")
                if target == 7:
                    raise MvdError(pos - 1, f"unknown block type {kind & 7} (byte {kind})")
                if target == DEM_MULTIPLE:
                    _need(data, pos, 4, "dem_multiple block")
                    to = _U32.unpack_from(data, pos)[0]
                    pos += 4
                elif target == DEM_ALL:
                    to = 0
                elif target == DEM_READ:  # goes to whom the block before went
                    target, to = self.last_type, self.last_to
                _need(data, pos, 4, "block length")
                size = _U32.unpack_from(data, pos)[0]
                pos += 4
                if size > n - pos:
                    raise _Short(pos, f"truncated block (its messages need {size} bytes, {n - pos} left)")
            except _Short as short:
                if final:
                    raise MvdError(short.offset, short.args[0]) from None
                return start
            self.time_ms, self.last_type, self.last_to = time_ms, target, to
            if not (target == DEM_MULTIPLE and to == 0):  # hidden data, not messages
                self._messages(data, pos, pos + size)
            pos += size
        return n

    def _check_start(self) -> None:
        """MvdError "not an MVD demo" unless the data begins with a block of messages whose first is
        svc_serverdata (module docstring); a client's .qwd is left to run()'s own message."""
        data = self.data
        kind = data[1] & 7 if len(data) >= 2 else None
        if kind == DEM_CMD:
            return
        first = 2 + (4 if kind == DEM_MULTIPLE else 0) + 4  # block header, slot mask, length
        if kind is None:
            problem = "it is 1 byte long"
        elif kind in (DEM_SET, 7):
            problem = f"its first block is of type {kind}, which carries no messages"
        elif len(data) <= first:
            problem = f"it ends at byte {len(data)}, before its first message"
        elif data[first] != SVC_SERVERDATA:
            problem = f"its first message is of type {data[first]}"
        else:
            return
        raise MvdError(0, f"not an MVD demo ({problem}; an MVD begins with svc_serverdata, type {SVC_SERVERDATA})")

    def _messages(self, data: bytes, start: int, end: int) -> None:
        cur, handlers = self.cur, self.handlers
        cur.data, cur.pos, cur.end = data, start, end
        while cur.pos < end:
            at = cur.pos
            cmd = data[at]
            cur.pos = at + 1
            body = FIXED_BODIES.get(cmd)
            if body is not None:
                cur.what = "svc" + body[0]
                cur.skip(body[1])
                continue
            handler = handlers.get(cmd)
            if handler is None:
                raise MvdError(at, f"unknown message type {cmd}")
            cur.what = "svc" + handler.__name__
            handler()

    # ---------------------------------------------------------------- small messages

    def _string(self) -> None:
        self.cur.string()

    def _disconnect(self) -> None:
        if self.cur.pos < self.cur.end:  # mvdsv ends a demo with svc_disconnect "EndOfDemo"
            self.cur.string()

    def _lightstyle(self) -> None:
        self.cur.skip(1)
        self.cur.string()

    def _sound(self) -> None:
        cur = self.cur
        channel = cur.ushort()
        cur.skip(1 + (1 if channel & 0x8000 else 0) + (1 if channel & 0x4000 else 0) + 3 * cur.coord_size)

    def _damage(self) -> None:
        self.cur.skip(2 + 3 * self.cur.coord_size)

    def _baseline(self) -> None:
        cur = self.cur
        cur.skip(4 + 3 * (cur.coord_size + (2 if cur.coord_size == 4 else 1)))

    def _spawnstatic(self) -> None:
        self._baseline()

    def _spawnbaseline(self) -> None:
        self.cur.skip(2)
        self._baseline()

    def _spawnstaticsound(self) -> None:
        self.cur.skip(3 * self.cur.coord_size + 3)

    def _intermission(self) -> None:
        cur = self.cur
        cur.skip(3 * cur.coord_size + 3 * (2 if cur.coord_size == 4 else 1))

    def _temp_entity(self) -> None:
        cur = self.cur
        kind = cur.byte()
        if kind in TE_BEAMS:
            cur.skip(2 + 6 * cur.coord_size)
        elif kind in TE_COUNTED:
            cur.skip(1 + 3 * cur.coord_size)
        elif kind in TE_POSITION_ONLY:
            cur.skip(3 * cur.coord_size)
        else:
            raise MvdError(cur.pos - 1, f"unknown temp entity type {kind}")

    def _nails(self) -> None:
        self.cur.skip(6 * self.cur.byte())

    def _nails2(self) -> None:
        self.cur.skip(7 * self.cur.byte())

    def _download(self) -> None:
        size = self.cur.short()
        self.cur.skip(1 + max(size, 0))

    def _list(self, count_bytes: int) -> list[bytes]:
        cur = self.cur
        cur.skip(count_bytes)
        names = []
        while True:
            name = cur.string()
            if not name:
                break
            names.append(name)
        cur.skip(1)
        return names

    def _modellist(self) -> None:
        self._note_models(self._list(1))

    def _modellistshort(self) -> None:
        self._note_models(self._list(2))

    def _note_models(self, names: list[bytes]) -> None:
        if names and not self.map_name and names[0].startswith(b"maps/"):  # model 1 is the world
            self.map_name = names[0][5:].rsplit(b".", 1)[0].decode("latin-1")

    def _soundlist(self) -> None:
        self._list(1)

    # ---------------------------------------------------------------- game state

    def _serverdata(self) -> None:
        cur = self.cur
        while True:
            protocol = cur.ulong()
            if protocol == PROTOCOL_VERSION_FTE:
                self.fte_ext = cur.ulong()
            elif protocol == PROTOCOL_VERSION_FTE2:
                cur.skip(4)
            elif protocol == PROTOCOL_VERSION_MVD1:
                self.mvd_ext = cur.ulong()
            else:
                break
        if not 24 <= protocol <= 28:
            raise MvdError(cur.pos - 4, f"unsupported protocol version {protocol}")
        cur.skip(4)  # servercount
        cur.string()  # game directory
        cur.skip(4)  # demo time
        self.level_title = quake_text(cur.string())
        if protocol >= 25:
            cur.skip(40)  # movevars
        cur.coord_size = 4 if self.fte_ext & FTE_PEXT_FLOATCOORDS else 2
        cur.entity_float = bool(self.mvd_ext & MVD_PEXT1_FLOATCOORDS)
        self.saw_serverdata = True

    def _stufftext(self) -> None:
        text = self.cur.string()
        if b"fullserverinfo" in text:
            info = text[text.find(b"\\") :].rstrip(b'\n" ')
            self.serverinfo.update(_info_pairs(info))

    def _serverinfo(self) -> None:
        key, value = self.cur.string(), self.cur.string()
        self.serverinfo[key.decode("latin-1")] = value

    def _slot(self) -> int:
        slot = self.cur.byte()
        if slot >= MAX_CLIENTS:
            raise MvdError(self.cur.pos - 1, f"{self.cur.what} for player slot {slot} (at most {MAX_CLIENTS - 1})")
        return slot

    def _updateuserinfo(self) -> None:
        slot = self._slot()
        self.cur.skip(4)  # userid
        self.userinfo[slot] = _info_pairs(self.cur.string())
        self._note_player(slot)

    def _setinfo(self) -> None:
        slot = self._slot()
        key, value = self.cur.string(), self.cur.string()
        self.userinfo.setdefault(slot, {})[key.decode("latin-1")] = value
        self._note_player(slot)

    def _note_player(self, slot: int) -> None:
        info = self.userinfo.get(slot, {})
        if info.get("name") and info.get("*spectator", b"0") in (b"", b"0"):
            self.ever_named[slot] = (quake_text(info["name"]), quake_text(info.get("team", b"")))

    def _playing_names(self) -> dict[str, int]:
        """Readable name -> slot of everyone in the game now (not spectators)."""
        names = {}
        for slot, info in self.userinfo.items():
            if info.get("name") and info.get("*spectator", b"0") in (b"", b"0"):
                names[quake_text(info["name"])] = slot
        return names

    def _setangle(self) -> None:
        slot = self._slot()
        self.cur.angle()
        self.cur.angle()
        self.cur.angle()
        self.fixangle[slot] = True

    def _set_stat(self, stat: int, value: int) -> None:
        column = STAT_COLUMN.get(stat)
        slot = self.last_to
        if column is None or slot >= MAX_CLIENTS or self.stat_now[slot][column] == value:
            return
        self.stat_now[slot][column] = value
        self.stat_changes.setdefault(slot, []).append((self.time_ms / 1000.0, *self.stat_now[slot]))

    def _updatestat(self) -> None:
        stat = self.cur.byte()
        self._set_stat(stat, self.cur.byte())

    def _updatestatlong(self) -> None:
        stat = self.cur.byte()
        self._set_stat(stat, self.cur.long())

    def _updatefrags(self) -> None:
        slot = self._slot()
        frags = self.cur.short()
        if self.stat_now[slot][FRAGS_COLUMN] != frags:
            self.stat_now[slot][FRAGS_COLUMN] = frags
            self.stat_changes.setdefault(slot, []).append((self.time_ms / 1000.0, *self.stat_now[slot]))

    def _print(self) -> None:
        level = self.cur.byte()
        text = self.cur.string()
        if level != PRINT_MEDIUM or self.last_type != DEM_ALL:  # obituaries go to everyone
            return
        self.print_buffer += text
        *lines, self.print_buffer = self.print_buffer.split(b"\n")
        for line in lines:
            names = self._playing_names()
            obituary = parse_obituary(quake_text(line), list(names))
            if obituary is not None:
                self.deaths.append(
                    MvdDeath(
                        self.time_ms / 1000.0, names.get(obituary.killer, -1), names.get(obituary.victim, -1), obituary.label
                    )
                )

    def _playerinfo(self) -> None:
        cur = self.cur
        data = cur.data
        slot = self._slot()
        at = cur.need(3)  # flags, animation frame
        flags = data[at] | data[at + 1] << 8
        size = cur.coord_size
        present = _PLAYERINFO_FIELDS[flags & _PLAYERINFO_MASK]
        at = cur.need(present[0] * size + present[1])
        origin, angles = self.origin[slot], self.angles[slot]
        for i in range(3):
            if flags & (DF_ORIGIN << i):
                origin[i] = _F32.unpack_from(data, at)[0] if size == 4 else _I16.unpack_from(data, at)[0] / 8.0
                at += size
        for i in range(3):
            if flags & (DF_ANGLES << i):
                angles[i] = _I16.unpack_from(data, at)[0] * (360.0 / 65536.0)
                at += 2
        dead = bool(flags & DF_DEAD)
        jump = self.fixangle[slot] or (self.dead[slot] and not dead)
        self.dead[slot], self.fixangle[slot] = dead, False
        self.samples.setdefault(slot, []).append((self.time_ms / 1000.0, *origin, *angles, jump, dead))

    # ---------------------------------------------------------------- entities (read past, not kept)

    def _delta(self, word: int) -> None:
        """CL_ParseDelta's reads for an entity whose first 16 bits were `word`."""
        cur = self.cur
        bits = word & ~511
        if bits & U_MOREBITS:
            bits |= cur.byte()
        more = 0
        if bits & U_FTE_EVENMORE and self.fte_ext:
            more = cur.byte()
            if more & U_FTE_YETMORE:
                more |= cur.byte() << 8
        n = 0
        if bits & U_MODEL:
            n += 1
        elif more & U_FTE_MODELDBL:
            n += 2
        n += bool(bits & U_FRAME) + bool(bits & U_COLORMAP) + bool(bits & U_SKIN) + bool(bits & U_EFFECTS)
        coord = 4 if cur.entity_float else cur.coord_size
        angle = 2 if cur.coord_size == 4 else 1
        n += coord * (bool(bits & U_ORIGIN1) + bool(bits & U_ORIGIN2) + bool(bits & U_ORIGIN3))
        n += angle * (bool(bits & U_ANGLE1) + bool(bits & U_ANGLE2) + bool(bits & U_ANGLE3))
        if more & U_FTE_TRANS and self.fte_ext & FTE_PEXT_TRANS:
            n += 1
        if more & U_FTE_COLOURMOD and self.fte_ext & FTE_PEXT_COLOURMOD:
            n += 3
        cur.skip(n)

    def _delta_from_short(self) -> None:
        self._delta(self.cur.ushort())

    def _entities(self) -> None:
        cur = self.cur
        while True:
            word = cur.ushort()
            if not word:
                return
            if word & U_REMOVE:
                if word & U_MOREBITS and self.fte_ext & FTE_PEXT_ENTITYDBL and cur.byte() & U_FTE_EVENMORE:
                    cur.skip(1)
                continue
            self._delta(word)

    def _packetentities(self) -> None:
        self._entities()

    def _deltapacketentities(self) -> None:
        self.cur.skip(1)  # the frame it deltas from
        self._entities()

    # ---------------------------------------------------------------- result

    def teamplay(self) -> int:
        try:
            return int(self.serverinfo.get("teamplay", b"0") or 0)
        except ValueError:
            return 0

    def demo(self) -> MvdDemo:
        slots = sorted(s for s in self.ever_named if s in self.samples)
        if not slots:
            raise MvdError(len(self.data), "no player in the demo (only spectators or no svc_playerinfo)")
        players = [MvdPlayer(s, *self.ever_named[s]) for s in slots]
        tracks = {}
        for s in slots:
            rows = np.array(self.samples[s], dtype=np.float64)
            tracks[s] = MvdTrack(
                time_s=rows[:, 0], origin_units=rows[:, 1:4], angles_deg=rows[:, 4:7], jump=rows[:, 7] > 0, dead=rows[:, 8] > 0
            )
        stats = {}
        for s in slots:
            changes = [(0.0, 0, 0, 0, 0)] + self.stat_changes.get(s, [])
            stats[s] = MvdStats(
                time_s=np.array([r[0] for r in changes], dtype=np.float64),
                values=np.array([r[1:] for r in changes], dtype=np.int64),
            )
        deaths = [d for d in self.deaths if d.killer in tracks or d.victim in tracks]
        map_name = self.map_name or self.serverinfo.get("map", b"").decode("latin-1")
        return MvdDemo(
            map_name=map_name,
            level_title=self.level_title,
            teamplay=self.teamplay(),
            duration_s=self.time_ms / 1000.0,
            players=players,
            tracks=tracks,
            stats=stats,
            deaths=deaths,
        )


@dataclass(frozen=True)
class MvdUpdate:
    """What one MvdStream.feed decoded: time_s, the demo time of its last block; teamplay as
    MvdDemo's; players, the
    playing slots named so far that have been seen (MvdDemo.players' rule); and, new since the
    feed before, each slot's samples (MvdTrack), stat changes (MvdStats without the time-0 row) and
    the deaths."""

    time_s: float
    teamplay: int
    players: list[MvdPlayer]
    tracks: dict[int, MvdTrack]
    stats: dict[int, MvdStats]
    deaths: list[MvdDeath]


class MvdStream:
    """The live decoder: an MVD fed as it comes, in chunks cut anywhere (a QTV stream), read with
    the same message decoding as parse_mvd; each feed answers what its whole blocks brought. A
    stream that is not an MVD, or bytes that are not its blocks, raise MvdError with the offset in
    the stream (the decoder is then spent: a new stream needs a new decoder)."""

    def __init__(self) -> None:
        self._reader = _Reader(b"")
        self._buffer = b""
        self._consumed = 0  # stream bytes before the buffer
        self._started = False

    @property
    def pending_bytes(self) -> int:
        """Bytes of a block not whole yet (a stream that ends with some was cut mid-block)."""
        return len(self._buffer)

    def feed(self, chunk: bytes) -> MvdUpdate:
        """Decodes the whole blocks chunk completes (class docstring)."""
        reader = self._reader
        self._buffer += chunk
        try:
            if not self._started:
                reader.data = self._buffer
                if len(self._buffer) < 11:  # the first block's header, slot mask, length, message
                    return self._update()
                reader._check_start()
                self._started = True
            used = reader.blocks(self._buffer, final=False)
        except MvdError as exc:
            raise MvdError(self._consumed + exc.offset, exc.reason) from None
        self._consumed += used
        self._buffer = self._buffer[used:]
        return self._update()

    def _update(self) -> MvdUpdate:
        r = self._reader
        slots = sorted(s for s in r.ever_named if s in r.samples)
        tracks = {}
        for s, rows in r.samples.items():
            if rows:
                a = np.array(rows, dtype=np.float64)
                tracks[s] = MvdTrack(
                    time_s=a[:, 0], origin_units=a[:, 1:4], angles_deg=a[:, 4:7], jump=a[:, 7] > 0, dead=a[:, 8] > 0
                )
                r.samples[s] = []  # the slot stays seen
        stats = {
            s: MvdStats(time_s=np.array([c[0] for c in rows]), values=np.array([c[1:] for c in rows], dtype=np.int64))
            for s, rows in r.stat_changes.items()
            if rows
        }
        r.stat_changes = {}
        deaths, r.deaths = r.deaths, []
        return MvdUpdate(r.time_ms / 1000.0, r.teamplay(), [MvdPlayer(s, *r.ever_named[s]) for s in slots], tracks, stats, deaths)


def parse_mvd(data: bytes) -> MvdDemo:
    """Reads a whole MVD (module docstring); MvdError for anything that is not one."""
    reader = _Reader(bytes(data))
    reader.run()
    return reader.demo()
