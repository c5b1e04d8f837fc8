"""The QTV bridge: a live QuakeWorld match read as a QTV client and directed as a RIG_MATCH session.

The client (`open_stream`) speaks QTV version 1 as ezQuake does (QW-Group/ezquake-source
src/qtv.c QTV_CL_HEADER, src/cl_demo.c CL_QTVPoll and its request): it sends "QTV", "VERSION: 1",
then "SOURCE: STREAM" when the URL names a stream on a proxy, else "RECEIVE" (the proxy's one
playing stream; QW-Group/qtv downstream_pending_request.go turns it into that SOURCE, mvdsv's
sv_demo_qtv.c ignores both), its USERINFO and a blank line. The source answers "QTVSV 1" and
header lines up to a blank line: BEGIN (alone or "BEGIN: server") says the MVD stream follows;
PERROR (permanent), TERROR or ERROR say why not, and are a QtvRefused naming the source and its
words. With a password (mvdsv's qtv_password) the request offers AUTH methods and a source that
answers AUTH and CHALLENGE instead of BEGIN gets a second request on the same connection with the
answer (qtv_auth.py); without one, a source that asks for a password is refused the same way.

The stream is MVD blocks as a recorded demo's (mvdsv SV_MVD_Record to a stream destination),
decoded as they come by matches/mvd_wire.py's MvdStream. QtvTracks keeps the players, timed by
the stream's own clock (the demo time its blocks' time deltas add up to), not by when their
bytes arrived: stream_clock.py maps demo time onto the local clock by the least delay of the
recent arrivals, rising slowly (a jitter buffer), so a segment that comes late or several that
come bunched keep the players' motion at the pace the server recorded it; a catch-up burst
brings the mapping down to its newest block at once (the burst lands in the past), and each new
connection, whose demo time starts anew, re-anchors it. Each sample is placed at its demo time's
local time; the players are sampled at t - interp_delay_s (the playout delay: a late segment's
margin), interpolated between the samples around it except into a jump (teleport, respawn:
mvd_wire's; a new connection's first sample), held beyond the newest; stale after hold_s without
any arrival; not started before the first sample of all (the frames begin with the players'
motion, not holding it over the playout delay). Each sample also says the stream's demo time it
shows (the samples' demo times interpolated the same way, held at the ends): a recorded program
(program_record.py) is placed on the match file of the same demo by it.
Stat changes and obituaries are placed by their demo time the same way and go out with the first
frame that shows their moment.
The roster is the first update's players (slot order: ids p00, p01, ..., the demo importer's;
teams by quakeworld_mvd.player_teams). A slot that starts playing later (a player joining during
the warm-up or mid-match), or a slot now playing under another name (another player took it),
changes the roster: its samples are kept from then on, `roster_changed` is set, and nothing of
it reaches the session (a session's targets are fixed when it opens) until the driver opens the
next session with `reopen()`'s roster (cast_qtv: the joiner gets the next id, its team the
roster's index of its team name, or a new one).
Obituaries become events: a kill (attacker, victim; a suicide or a death to the world names the
victim twice, as the importer does), or, where a teamkill line leaves a side unsaid, "death" of
the victim or "kill_unknown" of the killer.

QtvReceiver runs the connection on a thread: when the source drops, the stream ends (cut
mid-block or not) or bytes arrive that are no MVD, it logs one line saying which and reconnects
with exponential backoff, forever, with a fresh decoder (the source sends its whole state again);
the session (live_session.py) stays open meanwhile, holding the program once the players go stale.
A refusal, or a first connection that cannot be made, ends the cast with that error.
"""

from __future__ import annotations

import bisect
import dataclasses
import logging
import math
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlsplit

import numpy as np

import camdirector_client as cd
from camdirector.bridges import qtv_auth
from camdirector.bridges.gsi_tracks import DerivedEvent, Sample
from camdirector.bridges.live_session import CastCounts, drive_sessions
from camdirector.bridges.program_record import ProgramRecorder
from camdirector.bridges.stream_clock import StreamClock, StreamClockSettings
from camdirector.evaluation.match.match_file import MatchPlayer
from camdirector.geometry import quake_frame
from camdirector.matches.mvd_wire import MvdError, MvdPlayer, MvdStream, MvdUpdate
from camdirector.matches.quakeworld_mvd import player_teams, quake_player

log = logging.getLogger(__name__)

QTV_PORT = 27500  # mvdsv's default port, where it also takes QTV connections
HEADER_LIMIT_BYTES = 64 * 1024  # an answer's header past this is no QTV source's
RECENT_SAMPLES = 64  # samples kept per player: a few seconds of a server's frames


@dataclass(frozen=True)
class QtvSettings:
    """The QTV bridge (`camdirector cast qtv`): connection and the driver's clock."""

    rate_hz: float = 30.0  # frames sent to the server a second. [1, 120]
    delay_s: float = 10.0  # the broadcast delay the caster sets, s. [0, 300]
    interp_delay_s: float = 0.15  # players shown this far behind the stream clock (stream_clock.py): jitter absorbed, s. [0, 2]
    hold_s: float = 2.0  # players held this long without a sample, then stale (no frame sent), s. [0.1, 60]
    connect_timeout_s: float = 5.0  # TCP connect and the answer's header, s. [0.1, 60]
    read_timeout_s: float = 10.0  # no byte for this long: the source is gone, reconnect, s. [0.1, 300]
    backoff_s: float = 0.25  # first wait before reconnecting, doubled each failure, s. [0.01, 60]
    backoff_max_s: float = 5.0  # longest wait between reconnects, s. [backoff_s, 300]
    client_name: str = "camdirector"  # the USERINFO name the source shows for us; 1 to 31 printable characters
    password: str = ""  # the source's qtv_password; "" sends none. At most 255 printable characters, no quote
    stream_clock: StreamClockSettings = field(default_factory=StreamClockSettings)  # demo time onto the local clock

    def __post_init__(self):
        checks = [
            (1.0 <= self.rate_hz <= 120.0, "rate_hz must be in [1, 120]"),
            (0.0 <= self.delay_s <= 300.0, "delay_s must be in [0, 300]"),
            (0.0 <= self.interp_delay_s <= 2.0, "interp_delay_s must be in [0, 2]"),
            (0.1 <= self.hold_s <= 60.0, "hold_s must be in [0.1, 60]"),
            (0.1 <= self.connect_timeout_s <= 60.0, "connect_timeout_s must be in [0.1, 60]"),
            (0.1 <= self.read_timeout_s <= 300.0, "read_timeout_s must be in [0.1, 300]"),
            (0.01 <= self.backoff_s <= 60.0, "backoff_s must be in [0.01, 60]"),
            (self.backoff_s <= self.backoff_max_s <= 300.0, "backoff_max_s must be in [backoff_s, 300]"),
            (
                1 <= len(self.client_name) <= 31 and self.client_name.isprintable() and not set(self.client_name) & set('\\"\n'),
                "client_name must be 1 to 31 printable characters, no backslash or quote",
            ),
            (
                len(self.password) <= 255 and self.password.isprintable() and '"' not in self.password,
                "password must be at most 255 printable characters, no quote",
            ),
        ]
        bad = [message for ok, message in checks if not ok]
        if bad:
            raise ValueError("; ".join(bad))


class QtvError(Exception):
    """The QTV source could not be used: the message says which source and why."""


class QtvRefused(QtvError):
    """The source answered the request with an error (PERROR, TERROR, ERROR) or no stream."""


@dataclass(frozen=True)
class QtvAddress:
    """qtv://HOST[:PORT][/STREAM]: where the source listens and, on a proxy, which stream."""

    host: str
    port: int
    stream: str

    def __str__(self) -> str:
        return f"qtv://{self.host}:{self.port}" + (f"/{self.stream}" if self.stream else "")


def parse_qtv_url(url: str) -> QtvAddress:
    """ValueError unless url is qtv://HOST[:PORT][/STREAM] (port default 27500)."""
    parts = urlsplit(url)
    if parts.scheme != "qtv" or not parts.hostname or parts.query or parts.fragment:
        raise ValueError(f"{url!r}: give qtv://HOST:PORT or qtv://HOST:PORT/STREAM")
    try:
        port = parts.port or QTV_PORT
    except ValueError:
        raise ValueError(f"{url!r}: the port must be a number in [1, 65535]") from None
    stream = parts.path.strip("/")
    if not stream.isprintable() or "\n" in stream:
        raise ValueError(f"{url!r}: the stream must be printable")
    return QtvAddress(parts.hostname, port, stream)


def request_bytes(address: QtvAddress, client_name: str, auth: list[str] | None = None) -> bytes:
    """The client's request (module docstring); auth: the AUTH (and PASSWORD) lines to add."""
    lines = [
        "QTV",
        "VERSION: 1",
        f"SOURCE: {address.stream}" if address.stream else "RECEIVE",
        f"USERINFO: \\name\\{client_name}",
        *(auth or []),
    ]
    return ("\n".join(lines) + "\n\n").encode("latin-1")


def read_answer(sock: socket.socket, address: QtvAddress) -> tuple[dict[str, str], bytes]:
    """Reads the source's answer header (module docstring): its fields (name: value; BEGIN's
    value may be empty) and the stream bytes that came after it. QtvRefused for an error answer,
    QtvError for anything that is no QTV answer, OSError when the connection fails."""
    data = b""
    while b"\n\n" not in data:
        if len(data) > HEADER_LIMIT_BYTES:
            raise QtvError(f"{address}: no end to the answer's header after {HEADER_LIMIT_BYTES} bytes: not a QTV source")
        if data and not b"QTVSV ".startswith(data[:6]):
            break
        chunk = sock.recv(4096)
        if not chunk:
            raise QtvError(f"{address}: the source closed the connection before answering ({len(data)} bytes)")
        data += chunk
    if not data.startswith(b"QTVSV "):
        raise QtvError(f"{address}: not a QTV source (its answer begins {data[:24]!r})")
    header, rest = data.split(b"\n\n", 1)
    lines = header.decode("latin-1").split("\n")
    try:
        version = float(lines[0][6:].strip())
    except ValueError:
        raise QtvError(f"{address}: not a QTV answer ({lines[0]!r})") from None
    if int(version) != 1:
        raise QtvRefused(f"{address}: QTV protocol version {version:g}, this client speaks 1")
    fields = [(name.strip(), value.strip()) for name, _, value in (line.partition(":") for line in lines[1:])]
    errors = [f"{name}: {value}" for name, value in fields if name in ("PERROR", "TERROR", "ERROR")]
    if errors:
        raise QtvRefused(f"{address} refused the stream: {'; '.join(errors)}")
    return dict(fields), rest


def open_stream(address: QtvAddress, settings: QtvSettings) -> tuple[socket.socket, bytes]:
    """Connects, requests the stream (answering a password challenge: module docstring) and
    reads the answer: the connected socket (read timeout set) and the first stream bytes.
    QtvRefused for a refusal, a password asked and not given, or no BEGIN; QtvError as
    read_answer; OSError."""
    sock = socket.create_connection((address.host, address.port), timeout=settings.connect_timeout_s)
    try:
        offer = [f"AUTH: {method}" for method in qtv_auth.METHODS] if settings.password else []
        sock.sendall(request_bytes(address, settings.client_name, offer))
        try:
            fields, rest = read_answer(sock, address)
        except QtvRefused as exc:
            if settings.password or not any(word in str(exc).lower() for word in ("password", "auth")):
                raise
            raise QtvRefused(f"{exc} (it asks for a password: give it with --password)") from None
        if "BEGIN" not in fields and "AUTH" in fields:
            if not settings.password:
                raise QtvRefused(
                    f"{address} sent no stream: it asks for a password (AUTH: {fields['AUTH']}); give it (--password)"
                )
            try:
                reply = qtv_auth.answer(fields["AUTH"], fields.get("CHALLENGE", ""), settings.password)
            except ValueError as exc:
                raise QtvRefused(f"{address}: {exc}") from None
            sock.sendall(request_bytes(address, settings.client_name, [f"AUTH: {fields['AUTH']}", f'PASSWORD: "{reply}"']))
            fields, rest = read_answer(sock, address)
        if "BEGIN" not in fields:
            raise QtvRefused(f"{address} sent no stream: its answer holds no BEGIN ({sorted(fields)})")
        sock.settimeout(settings.read_timeout_s)
    except BaseException:
        sock.close()
        raise
    return sock, rest


@dataclass
class _Player:
    """One roster player's recent samples on the local clock: rows (t, x, y, z, yaw_deg, jump)."""

    slot: int
    rows: deque = field(default_factory=lambda: deque(maxlen=RECENT_SAMPLES))
    stats: tuple[int, int, int, int] = (0, 0, 0, 0)


class QtvTracks:
    """The live players (module docstring): offer(update, now_s) from the receiver's thread,
    sample(now_s) from the driver's."""

    def __init__(self, interp_delay_s: float, hold_s: float, stream_clock: StreamClockSettings = StreamClockSettings()):
        self.interp_delay_s, self.hold_s = interp_delay_s, hold_s
        self.clock = StreamClock(stream_clock)
        self._lock = threading.Lock()
        self._roster_ready = threading.Event()
        self.roster: list[MatchPlayer] = []
        self._players: dict[int, _Player] = {}  # slot -> state
        self._ids: dict[int, str] = {}
        self._stats_due: list[tuple[float, int, tuple[int, int, int, int]]] = []  # (local t, slot, values) not shown yet
        self._events_due: list[tuple[float, DerivedEvent]] = []  # (local t, event) not sent yet
        self._last_offer_s = -math.inf
        # (local t, demo time s, first of its stream) of the newest samples
        self._demo_clock: deque = deque(maxlen=RECENT_SAMPLES)
        self._first_due_s = math.inf  # local t of the first sample of all (a new connection's come later), s
        self._stream_start: set[int] = set()  # slots whose next sample is their first of a new connection's stream
        self.kills: list[tuple[str, str]] = []  # (attacker, victim) ids of every kill event, in order
        self.roster_changed = threading.Event()  # a slot joined or was renamed: reopen() gives the next roster
        self._changes: dict[int, MvdPlayer] = {}  # slot -> the player joining or renamed there, not in the roster yet
        self._teamplay = 0

    def wait_roster(self, timeout_s: float) -> bool:
        return self._roster_ready.wait(timeout_s)

    def new_stream(self) -> None:
        """A new connection's stream follows: its demo time starts anew (re-anchors the clock), and
        what it shows first is reached as a jump (held until then, never swept: a reconnect)."""
        with self._lock:
            self._stream_start = set(self._players) | {-1}  # -1: the demo clock's
            self.clock.reanchor()

    def offer(self, update: MvdUpdate, now_s: float) -> None:
        """Takes in what a segment that arrived at local time now_s decoded."""
        with self._lock:
            if not self.roster and update.players:
                self._fix_roster(update)
            if not self.roster:
                return
            self._note_changes(update)
            if update.tracks:
                self.clock.arrive(update.time_s, now_s)
            for slot, track in update.tracks.items():
                player = self._players.get(slot)
                if player is None:
                    continue
                self._last_offer_s = now_s
                feet = quake_frame.feet_world(track.origin_units)
                for k in range(len(track.time_s)):
                    t = self.clock.local_of(float(track.time_s[k]))
                    if player.rows and t <= player.rows[-1][0]:
                        continue  # a reconnect's burst of what was already had
                    first = slot in self._stream_start
                    self._stream_start.discard(slot)
                    player.rows.append((t, *feet[k], float(track.angles_deg[k, 1]), bool(track.jump[k]) or first))
                    if not self._demo_clock:
                        self._first_due_s = t
                    if not self._demo_clock or t > self._demo_clock[-1][0]:
                        self._demo_clock.append((t, float(track.time_s[k]), -1 in self._stream_start))
                        self._stream_start.discard(-1)
            for slot, stats in update.stats.items():
                if slot in self._players:
                    for time_s, (health, armor, items, frags) in zip(stats.time_s.tolist(), stats.values.tolist()):
                        self._stats_due.append((self.clock.local_of(time_s), slot, (health, armor, items, frags)))
            for death in update.deaths:
                self._note_death(death.killer, death.victim, self.clock.local_of(death.time_s))

    def _fix_roster(self, update: MvdUpdate) -> None:
        self._teamplay = update.teamplay
        for k, ((team, team_name), p) in enumerate(zip(player_teams(update), update.players, strict=True)):
            pid = f"p{k:02d}"
            self._ids[p.slot] = pid
            self._players[p.slot] = _Player(p.slot)
            self.roster.append(quake_player(pid, p.name, team, team_name))
        self._roster_ready.set()

    def _note_changes(self, update: MvdUpdate) -> None:
        """A slot playing that the roster lacks, or names otherwise, is a change (module docstring);
        a joiner's samples are kept from now on."""
        slot_of = {pid: slot for slot, pid in self._ids.items()}
        roster_names = {slot_of[p.id]: p.name for p in self.roster}  # slot -> its name in the roster
        for p in update.players:
            if roster_names.get(p.slot) == p.name:
                self._changes.pop(p.slot, None)  # renamed back before the next session
            elif self._changes.get(p.slot) != p:
                self._changes[p.slot] = p
                if p.slot not in self._players:
                    self._ids[p.slot] = f"p{len(self._ids):02d}"
                    self._players[p.slot] = _Player(p.slot)
                self.roster_changed.set()

    def reopen(self) -> list[MatchPlayer]:
        """The roster with every change so far (module docstring), for the next session; the players
        who joined or were renamed. Clears roster_changed."""
        with self._lock:
            teams = {p.team_name: p.team for p in self.roster if self._teamplay and p.team_name}
            changed = []
            for slot, p in sorted(self._changes.items()):
                pid = self._ids[slot]
                team_name = p.team if self._teamplay else ""
                if team_name and team_name not in teams:
                    teams[team_name] = max([*teams.values(), -1]) + 1
                at = next((k for k, q in enumerate(self.roster) if q.id == pid), None)
                own = len(self.roster) if at is None else self.roster[at].team  # without team names, a team of its own
                team = teams[team_name] if team_name else own
                player = quake_player(pid, p.name, team, team_name)
                if at is None:
                    self.roster.append(player)
                else:
                    self.roster[at] = player
                changed.append(player)
            self._changes.clear()
            self.roster_changed.clear()
            return changed

    def _note_death(self, killer: int, victim: int, t: float) -> None:
        """The death's event, due at local time t (sent with the frame that shows its moment)."""
        killer_id, victim_id = self._ids.get(killer), self._ids.get(victim)
        if victim_id is not None and killer_id is not None:
            kind, actor, other = "kill", killer_id, victim_id
        elif victim_id is not None and killer < 0:
            kind, actor, other = "death", victim_id, ""
        elif killer_id is not None and victim < 0:
            kind, actor, other = "kill_unknown", killer_id, ""
        else:
            return  # someone outside the session
        if kind == "kill":
            self.kills.append((actor, other))
        rows = self._players[victim if victim_id is not None else killer].rows
        where = _at(rows, t)[0] if rows else np.zeros(3)
        self._events_due.append((t, DerivedEvent(kind, actor, other, where)))

    def sample(self, now_s: float) -> Sample:
        with self._lock:
            stale = now_s - self._last_offer_s > self.hold_s
            at = now_s - self.interp_delay_s
            if at < self._first_due_s:  # the stream's first sample not yet due (inf before any)
                return Sample.not_started(stale)
            in_session = {p.id for p in self.roster}  # a joiner's samples, stats and events wait out (module docstring)
            ids, positions, yaws = [], [], []
            for slot, player in self._players.items():
                if not player.rows or self._ids[slot] not in in_session:
                    continue
                ids.append(self._ids[slot])
                position, yaw = _at(player.rows, at)
                positions.append(position)
                yaws.append(yaw)
            stats, events = [], []
            if not stale:  # while stale, what is due waits for the frames to go on
                changed = set()
                for _, slot, values in [d for d in self._stats_due if d[0] <= at]:
                    self._players[slot].stats = values
                    changed.add(slot)
                self._stats_due = [d for d in self._stats_due if d[0] > at]
                stats = [(self._ids[s], *self._players[s].stats) for s in sorted(changed) if self._ids[s] in in_session]
                events = [e for t, e in self._events_due if t <= at and e.names_only(in_session)]
                self._events_due = [(t, e) for t, e in self._events_due if t > at]
            demo_s = _demo_at(self._demo_clock, at)
            return Sample(
                ids=ids,
                positions_world=np.array(positions, dtype=np.float64).reshape(-1, 3),
                yaw_deg=np.array(yaws, dtype=np.float64),
                stats=stats,
                events=events,
                stale=stale or not ids,
                source_time_s=demo_s,
            )


def _local_t(row: tuple) -> float:
    return row[0]


def _demo_at(clock: deque, t: float) -> float | None:
    """The demo time shown at local time t: interpolated as the players are, held before a new
    stream's first sample (module docstring); None before any."""
    if not clock:
        return None
    after = bisect.bisect_right(clock, t, key=_local_t)
    if after == len(clock):
        return clock[-1][1]
    if after == 0:
        return clock[0][1]
    (ta, da, _), (tb, db, jump) = clock[after - 1], clock[after]
    return da if jump else da + (t - ta) / max(tb - ta, 1e-6) * (db - da)


def _at(rows: deque, t: float) -> tuple[np.ndarray, float]:
    """A player's feet (3,) m and yaw at local time t (module docstring)."""
    newest = rows[-1]
    if t >= newest[0]:
        return np.array(newest[1:4]), newest[4]
    after = bisect.bisect_right(rows, t, key=_local_t)  # rows rise in t: the first after t
    if after == 0:
        return np.array(rows[0][1:4]), rows[0][4]
    a, b = rows[after - 1], rows[after]
    if b[5]:  # jumped into b: hold a until then
        return np.array(a[1:4]), a[4]
    w = (t - a[0]) / max(b[0] - a[0], 1e-6)
    turn = (b[4] - a[4] + 180.0) % 360.0 - 180.0
    return np.array(a[1:4]) + w * (np.array(b[1:4]) - np.array(a[1:4])), a[4] + w * turn


@dataclass
class ReceiverCounts:
    """connections made, drops (a connection that ended or failed after BEGIN), bad_streams (bytes
    that were no MVD), bytes received, last_error (the newest error line)."""

    connections: int = 0
    drops: int = 0
    bad_streams: int = 0
    bytes: int = 0
    last_error: str = ""


class QtvReceiver:
    """Reads the source on a thread into tracks, reconnecting (module docstring). `error` is the
    QtvError that ended it, if one did (the cast stops then)."""

    def __init__(
        self, address: QtvAddress, settings: QtvSettings, tracks: QtvTracks, stop: threading.Event, clock: Callable[[], float]
    ):
        self.address, self.settings, self.tracks, self.stop, self.clock = address, settings, tracks, stop, clock
        self.counts = ReceiverCounts()
        self.error: QtvError | None = None
        self._sock: socket.socket | None = None
        self._thread = threading.Thread(target=self._run, name="qtv-receiver", daemon=True)

    def __enter__(self) -> QtvReceiver:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop.set()
        sock = self._sock
        if sock is not None:
            sock.close()  # unblocks recv
        self._thread.join(timeout=5.0)

    def _fail(self, error: QtvError) -> None:
        self.error = error
        self.counts.last_error = str(error)
        log.error("%s", error)
        self.stop.set()

    def _run(self) -> None:
        failures = 0
        while not self.stop.is_set():
            try:
                self._sock, rest = open_stream(self.address, self.settings)
            except QtvError as exc:
                self._fail(exc)
                return
            except OSError as exc:
                if not self.counts.connections:
                    self._fail(QtvError(f"cannot reach the QTV source {self.address}: {exc}"))
                    return
                self._retry(f"reconnecting to {self.address} failed: {exc}", failures)
                failures += 1
                continue
            self.counts.connections += 1
            failures = 0
            why = self._read(self._sock, rest)
            self._sock.close()
            self._sock = None
            if not self.stop.is_set():
                self.counts.drops += 1
                self._retry(why, 0)

    def _retry(self, why: str, failures: int) -> None:
        wait_s = min(self.settings.backoff_max_s, self.settings.backoff_s * 2.0**failures)
        self.counts.last_error = why
        log.warning("%s; reconnecting in %.2f s", why, wait_s)
        self.stop.wait(wait_s)

    def _read(self, sock: socket.socket, first: bytes) -> str:
        """Feeds the stream to the tracks until it ends; what ended it, as an error line."""
        decoder = MvdStream()
        self.tracks.new_stream()
        chunk = first
        try:
            while True:
                if chunk:
                    self.counts.bytes += len(chunk)
                    self.tracks.offer(decoder.feed(chunk), self.clock())
                chunk = sock.recv(65536)
                if not chunk:
                    cut = f", cut {decoder.pending_bytes} bytes into a block" if decoder.pending_bytes else ""
                    return f"the QTV source {self.address} closed the stream{cut}"
        except MvdError as exc:
            self.counts.bad_streams += 1
            return f"bad stream from {self.address}: not MVD data at stream byte {exc.offset}: {exc.reason}"
        except TimeoutError:
            return f"the QTV source {self.address} sent nothing for {self.settings.read_timeout_s:g} s"
        except OSError as exc:
            return f"the connection to {self.address} failed: {exc}"


@dataclass
class QtvCast:
    """What a cast did: the sessions' counts together (one more session each time the roster
    changed) and the receiver's."""

    session: CastCounts
    receiver: ReceiverCounts


def program_part(path: Path, k: int) -> Path:
    """Where session k (from 0) of a cast writes its program: path itself, then NAME.k.SUFFIX."""
    return path if k == 0 else path.with_name(f"{path.stem}.{k}{path.suffix}")


def cast_qtv(
    client: cd.Client,
    url: str,
    settings: QtvSettings,
    *,
    level: str,
    director: str,
    stop: threading.Event,
    clock: Callable[[], float] = time.monotonic,
    on_session: Callable[[str, list[MatchPlayer]], None] = lambda session_id, roster: None,
    on_progress: Callable[[CastCounts, ReceiverCounts, QtvTracks], None] = lambda counts, receiver, tracks: None,
    progress_s: float = 1.0,
    program_out: Path | None = None,
) -> QtvCast:
    """The bridge as a library call: reads the QTV source at url and drives a RIG_MATCH session
    on level until `stop` is set (module docstring). When the roster changes (a player joins or
    takes a slot) the session closes and the next opens with the new roster at once: the program
    starts again after the delay (a session's players are fixed when it opens). program_out:
    write the program received there as it comes (program_record.py), each later session's
    beside it (program_part). ValueError: a bad url; OSError: program_out cannot be written;
    QtvError: the source refused the stream or could not be reached first; DirectorError: the
    server refused a session or its stream failed."""
    address = parse_qtv_url(url)
    tracks = QtvTracks(settings.interp_delay_s, settings.hold_s, settings.stream_clock)
    parts = 0  # the program file's parts: one per session
    recorder = None if program_out is None else ProgramRecorder(program_out)

    def opened(session_id: str) -> None:
        roster = list(tracks.roster)
        if recorder is not None:
            recorder.begin(
                {
                    "program_of": str(address),
                    "level": level,
                    "director": director,
                    "delay_s": settings.delay_s,
                    "rate_hz": settings.rate_hz,
                    "roster": [dataclasses.asdict(p) for p in roster],
                }
            )
        on_session(session_id, roster)

    def next_part(changed: list[MatchPlayer]) -> None:
        nonlocal recorder, parts
        parts += 1
        if recorder is not None:
            assert program_out is not None
            recorder.close()
            recorder = ProgramRecorder(program_part(program_out, parts))

    try:
        with QtvReceiver(address, settings, tracks, stop, clock) as receiver:
            counts = drive_sessions(
                client,
                tracks,
                stop=stop,
                on_reopen=next_part,
                rate_hz=settings.rate_hz,
                delay_s=settings.delay_s,
                level=level,
                director=director,
                clock=clock,
                on_frame=lambda frame, time_s, sample: None if recorder is None else recorder.sent(frame, time_s, sample),
                on_reply=lambda reply: None if recorder is None else recorder.reply(reply),
                on_session=opened,
                on_progress=lambda c: on_progress(c, receiver.counts, tracks),
                progress_s=progress_s,
            )
    finally:
        if recorder is not None:
            recorder.close()
    if receiver.error is not None:
        raise receiver.error
    return QtvCast(counts, receiver.counts)
