"""matches/quakeworld_mvd.py (and mvd_wire.py, quakeworld_obituaries.py): QuakeWorld MVD demos to
match files. A hand-built demo with exact expectations, the five development demos of
tests/data/real_matches/ (SOURCES.md) judged by what the demo says elsewhere (health stats,
scoreboard, the bravado duel's ktxstats.json), and bad bytes that must give MvdError."""

from __future__ import annotations

import gzip
import json
import struct
from pathlib import Path

import numpy as np
import pytest

from camdirector.__main__ import main
from camdirector.evaluation.match.match_file import STAT_COLUMNS, load_match
from camdirector.geometry import quake_frame
from camdirector.geometry.transforms import quat_to_matrix
from camdirector.matches.mvd_wire import quake_text
from camdirector.matches.quakeworld_mvd import STEP_SPEED_UNITS_S, MvdError, import_mvd, match_from_mvd, parse_mvd
from camdirector.matches.quakeworld_obituaries import Obituary, parse_obituary
from tests.evaluation.match.test_match_file import assert_stands_and_aims

DATA = Path(__file__).resolve().parents[1] / "data" / "real_matches"
DEMOS = {
    "4on4": "4on4_s_vs_pol_dm2_20241118-2135.mvd.gz",
    "2on2": "2on2_sf_vs_red_frobodm2_220104-0915.mvd.gz",
    "duel": "duel_holy_vs_dago_bravado_20240426-1659.mvd.gz",
    "1on1": "1on1_milton_vs_mushi_tron_20240616-1719.mvd.gz",
    "wipeout": "wipeout_red_vs_blue_q3dm6qw_20240406-2028.mvd.gz",
}
# (map, [(name, team index)]) as the demos' userinfo and serverinfo say.
EXPECTED = {
    "4on4": (
        "dm2",
        [("bps", 0), ("goblin", 0), ("maCLer", 1), ("irn", 1), ("tom", 1), ("andeh", 0), ("carapace", 0), ("ThundeR", 1)],
    ),
    "2on2": ("frobodm2", [("Final", 0), (": Timber", 1), ("> MrJustice", 0), (": Sujoy", 1)]),
    "duel": ("bravado", [("HoLy", 0), ("dago", 1)]),
    "1on1": ("tron", [("mushi", 0), ("Milton", 1)]),
    "wipeout": ("q3dm6qw", [("z0mbie90", 0), ("Kalle Dangerous", 1), ("j0rmund", 1), ("lurq", 0), ("grotzky", 1)]),
}
M_PER_S_MAX = STEP_SPEED_UNITS_S * quake_frame.M_PER_UNIT  # 2000 units/s per axis: 108 m/s


@pytest.fixture(scope="module")
def demos() -> dict:
    """name -> (raw bytes, MvdDemo, MvdImport), each demo parsed once."""
    out = {}
    for key, file in DEMOS.items():
        data = gzip.decompress((DATA / file).read_bytes())
        demo = parse_mvd(data)
        out[key] = (data, demo, match_from_mvd(demo))
    return out


# ------------------------------------------------------------------ a hand-built demo


def _block(target: int, body: bytes, msec: int = 0, to: int = 0) -> bytes:
    return bytes([msec, target | (to << 3)]) + struct.pack("<I", len(body)) + body


def _tiny_demo(pitch_angle16: int = 0) -> tuple[bytes, list[int]]:
    """serverdata, one player "ab" of team "red", its stats and frags, two playerinfo frames 0.1 s
    apart (origin (0, 0, 24) -> (32, 0, 24) units, looking along yaw 90 and pitch_angle16 * 360 /
    65536 deg), then "ab suicides". Returns the bytes and the offsets where its blocks end."""
    serverdata = (
        bytes([11])
        + struct.pack("<ii", 28, 7)
        + b"qw\0"
        + struct.pack("<f", 0.0)
        + b"Tiny Level\0"
        + struct.pack("<10f", *([1.0] * 10))
    )
    modellist = bytes([45, 0]) + b"maps/tiny.bsp\0progs/player.mdl\0\0" + bytes([0])
    userinfo = bytes([40, 0]) + struct.pack("<i", 1) + b"\\name\\ab\\team\\red\0"
    stats = bytes([3, 0, 100, 3, 4, 50, 38, 15]) + struct.pack("<i", 4097)
    first = (
        bytes([14, 0])
        + struct.pack("<h", 3)
        + bytes([42, 0])
        + struct.pack("<H", 0b11111)
        + bytes([0])
        + struct.pack("<hhhhh", 0, 0, 24 * 8, pitch_angle16, 16384)
    )
    second = bytes([42, 0]) + struct.pack("<H", 0b1) + bytes([0]) + struct.pack("<h", 32 * 8)
    obituary = bytes([8, 1]) + b"ab suicides\n\0"
    blocks = [
        _block(6, serverdata + modellist + userinfo),
        _block(5, stats, to=0),
        _block(6, first),
        _block(6, second, msec=100),
        _block(6, obituary),
    ]
    ends = list(np.cumsum([len(b) for b in blocks]))
    return b"".join(blocks), ends


def test_a_hand_built_demo_imports_exactly():
    data, _ = _tiny_demo()
    match = import_mvd(data, rate_hz=20.0)
    assert match.level == "tiny"
    assert [(p.id, p.name, p.team) for p in match.players] == [("p00", "ab", 0)]
    np.testing.assert_allclose(match.time_s, [0.0, 0.05, 0.1])
    np.testing.assert_allclose(match.positions_world[:, 0], [[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [1.0, 0.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(match.rotations_xyzw[:, 0], np.tile(quake_frame.view_rotation(0.0, 90.0), (3, 1)), atol=1e-12)
    assert STAT_COLUMNS == ("health", "armor", "items", "frags")
    assert match.stats.tolist() == [[[100, 50, 4097, 3]]] * 3
    [kill] = match.events
    assert (kill.kind, kill.actor_id, kill.other_actor_id, kill.label, kill.time_s) == ("kill", "p00", "p00", "suicide", 0.1)
    np.testing.assert_allclose(kill.position_world, [1.0, 0.0, 0.0], atol=1e-12)
    assert match.alive[:, 0].tolist() == [True, True, False]  # dead from the kill on: no respawn follows


def test_a_grid_a_phase_of_a_row_later_samples_between_the_rows():
    """phase_rows 0.5 at 20 Hz: the 40 Hz grid's odd rows, the same interpolation there."""
    data, _ = _tiny_demo()
    half, fine = import_mvd(data, rate_hz=20.0, phase_rows=0.5), import_mvd(data, rate_hz=40.0)
    np.testing.assert_allclose(half.time_s[:2], fine.time_s[1::2][:2], rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(half.positions_world[:2], fine.positions_world[1::2][:2], rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(half.positions_world[:2, 0, 0], [0.25, 0.75], atol=1e-12)
    for phase in (-0.1, 1.0, float("nan")):
        with pytest.raises(ValueError, match="phase_rows"):
            import_mvd(data, rate_hz=20.0, phase_rows=phase)


def test_a_player_looking_down_stands_upright_and_keeps_its_aim():
    """Pitch 60 deg (the nearest 16-bit angle): the body turns by the yaw alone, the aim has both."""
    angle16 = round(60.0 * 65536 / 360.0)
    match = import_mvd(_tiny_demo(angle16)[0], rate_hz=20.0)
    for frame in range(len(match.time_s)):
        assert_stands_and_aims(match, frame, 0, angle16 * 360.0 / 65536.0, 90.0)
    np.testing.assert_allclose(match.aim_pitch_deg[:, 0], angle16 * 360.0 / 65536.0, rtol=0.0, atol=1e-12)


def test_every_real_players_body_stands(demos):
    for key, (_, _, imported) in demos.items():
        up = np.einsum("fpij,j->fpi", quat_to_matrix(imported.match.rotations_xyzw), [0.0, 1.0, 0.0])
        assert np.abs(up - [0.0, 1.0, 0.0]).max() <= 1e-9, key
        assert np.abs(imported.match.aim_pitch_deg).max() > 30.0, key  # the players did look up and down


def test_a_demo_cut_anywhere_is_an_mvd_error_or_a_shorter_demo():
    data, ends = _tiny_demo()
    for cut in range(len(data)):
        try:
            import_mvd(data[:cut])
        except MvdError as exc:
            assert 0 <= exc.offset <= cut and str(exc).startswith(f"offset {exc.offset}: ")
        else:
            assert cut in ends, f"cut at {cut} inside a block parsed"


def test_unknown_messages_and_bad_blocks_name_their_offset():
    data, ends = _tiny_demo()
    bad = data + _block(6, bytes([1, 1, 200]))
    with pytest.raises(MvdError, match=f"offset {len(data) + 8}: unknown message type 200"):
        parse_mvd(bad)
    with pytest.raises(MvdError, match="offset 0: empty file"):
        parse_mvd(b"")
    with pytest.raises(MvdError, match=r"truncated svc_playerinfo \(needs 2 bytes, 0 left\)"):
        parse_mvd(data[: ends[2]] + _block(6, bytes([42, 0]) + struct.pack("<H", 1) + bytes([0])))
    with pytest.raises(MvdError, match="not a server's MVD"):
        parse_mvd(bytes([0, 0]) + data)


def _begins_with_serverdata(data: bytes) -> bool:
    """Whether data's first block is one of messages whose first is svc_serverdata (11)."""
    if len(data) < 2 or data[1] & 7 in (0, 2, 7):
        return False
    first = 2 + (4 if data[1] & 7 == 3 else 0) + 4
    return len(data) > first and data[first] == 11


def test_random_bytes_are_an_mvd_error_that_says_not_an_mvd_demo():
    rng = np.random.default_rng(29)
    said = 0
    for _ in range(200):
        junk = rng.integers(0, 256, int(rng.integers(1, 4000)), dtype=np.uint8).tobytes()
        with pytest.raises(MvdError) as refused:
            parse_mvd(junk)
        if junk[1:2] and junk[1] & 7 == 0:
            assert "a client's .qwd demo" in str(refused.value)
        elif not _begins_with_serverdata(junk):
            assert str(refused.value).startswith("offset 0: not an MVD demo (") and "truncated" not in str(refused.value)
            said += 1
    assert said >= 150
    with pytest.raises(MvdError, match=r"^offset 0: not an MVD demo \(its first message is of type 255; "):
        parse_mvd(b"\x05\x06\xff\xff\xff\x7f" + bytes([255]))


def test_obituaries_name_both_sides_and_the_weapon():
    names = ["a b", "a", "rides", "x's"]
    assert parse_obituary("a b rides x's's rocket", names) == Obituary("x's", "a b", "rl")
    assert parse_obituary("a was crushed by his teammate", names) == Obituary("", "a", "teamkill:stomp")
    assert parse_obituary("a was crushed by rides", names) == Obituary("rides", "a", "stomp")
    assert parse_obituary("rides checks his glasses", names) == Obituary("rides", "", "teamkill")
    assert parse_obituary("a b discovers blast radius", names) == Obituary("a b", "a b", "suicide:rl")
    assert parse_obituary("a cratered", names) == Obituary("a", "a", "world:fall")
    assert parse_obituary("nobody cratered", names) is None
    assert quake_text(bytes([0xE4, 0xE1, 0x12, 0x9B, 0x10])) == "da09["


# ------------------------------------------------------------------ the development demos


def test_every_demo_imports_with_its_map_names_and_teams(demos):
    for key, (_, _, imported) in demos.items():
        match = imported.match
        level, players = EXPECTED[key]
        assert match.level == level
        assert [(p.name, p.team) for p in match.players] == players
        assert np.all(np.isfinite(match.positions_world)) and np.all(np.isfinite(match.rotations_xyzw))
        np.testing.assert_allclose(np.linalg.norm(match.rotations_xyzw, axis=2), 1.0, atol=1e-9)
        assert match.stats.dtype == np.int32 and match.stats.shape == (len(match.time_s), len(players), 4)


def test_the_4on4_has_eight_players_in_two_teams_of_four(demos):
    match = demos["4on4"][2].match
    assert len(match.players) == 8
    assert sorted(p.team for p in match.players) == [0, 0, 0, 0, 1, 1, 1, 1]
    team = {p.id: p.team for p in match.players}
    teamkills = [e for e in match.events if e.label.startswith("teamkill")]
    assert teamkills and all(team[e.actor_id] == team[e.other_actor_id] and e.actor_id != e.other_actor_id for e in teamkills)


def test_a_team_game_names_its_teams_and_a_duel_none(demos):
    four = demos["4on4"][2].match
    names = {(p.team, p.team_name) for p in four.players}  # one name per team, as its userinfo says
    assert len(names) == 2 and len({name for _, name in names}) == 2 and all(name for _, name in names)
    assert [p.team_name for p in demos["1on1"][2].match.players] == ["", ""]


def test_frags_at_the_end_are_the_last_scoreboard_and_the_obituaries_sum(demos):
    """The last frame's frags are each slot's last svc_updatefrags; in the demos that score as
    KTX's ClientObituary does they are also its sum over the obituaries: +1 a frag, -1 a death to
    the world, a suicide or a teamkill (to the killer), -2 the kill command. (Not wipeout, whose
    rounds score otherwise, nor the 1on1, a hoonymode duel: a suicide scores the opponent.)"""
    for key, (_, demo, imported) in demos.items():
        match = imported.match
        assert match.stats[-1, :, 3].tolist() == [int(demo.stats[p.slot].values[-1, 3]) for p in demo.players]
        if key in ("wipeout", "1on1"):
            continue
        frags = dict.fromkeys([p.id for p in match.players], 0)
        for e in match.events:
            frags[e.actor_id] += (
                -2 if e.label == "suicide" else -1 if e.actor_id == e.other_actor_id or e.label.startswith("teamkill") else 1
            )
        assert list(frags.values()) == match.stats[-1, :, 3].tolist(), key


def test_the_bravado_duel_agrees_with_its_ktxstats(demos):
    stats = json.loads((DATA / "duel_holy_vs_dago_bravado_20240426-1659.mvd.ktxstats.json").read_text())
    match = demos["duel"][2].match
    by_name = {quake_text(p["name"].encode("latin-1")): p["stats"] for p in stats["players"]}
    assert sorted(by_name) == sorted(p.name for p in match.players)
    for column, player in enumerate(match.players):
        judge = by_name[player.name]
        assert match.stats[-1, column, 3] == judge["frags"]
        assert sum(e.other_actor_id == player.id for e in match.events) == judge["deaths"]
        assert sum(e.actor_id == player.id != e.other_actor_id for e in match.events) == judge["kills"]
        assert sum(e.actor_id == player.id == e.other_actor_id for e in match.events) == judge["suicides"]


def test_kills_are_as_many_as_deaths_and_each_victim_dies_then_respawns(demos):
    for key, (_, demo, imported) in demos.items():
        match = imported.match
        assert len(match.events) == len(demo.deaths) > 0
        if key != "wipeout":  # wipeout respawns in the frame of the death: health never shows it
            drops = sum(int(np.sum((s.values[1:, 0] <= 0) & (s.values[:-1, 0] > 0))) for s in demo.stats.values())
            assert len(match.events) == drops, key
        index = match.player_index()
        for e in match.events:
            victim, f = index[e.other_actor_id], int(np.searchsorted(match.time_s, e.time_s))
            assert not match.alive[f, victim], (key, e)  # dead on the first frame at or after the kill
            if not match.alive[f:, victim].any():  # no respawn: the match ended soon after
                assert match.time_s[-1] - e.time_s < 30.0, (key, e)
            np.testing.assert_allclose(e.position_world, match.positions_world[f, victim], atol=2.0)


def test_players_move_at_running_speeds_except_where_they_jump(demos):
    """Between frames, a player moves at most 2000 units/s per axis (sv_maxvelocity, 108 m/s)
    unless flagged as a teleport or respawn; a living player's median speed is near QuakeWorld's
    running speed, 320 units/s = 10 m/s (Quake's 1/32 m per unit)."""
    for key, (_, _, imported) in demos.items():
        match, steps = imported.match, imported.steps
        speed = np.linalg.norm(np.diff(match.positions_world, axis=0), axis=2) * match.rate_hz
        assert speed[~steps].max() <= M_PER_S_MAX, key
        running = speed[~steps & match.alive[1:] & match.alive[:-1]]
        assert 5.0 < np.median(running) < 15.0, key
        assert steps.sum() >= len(match.events) * 0.5, key  # respawns are flagged


def test_a_real_demo_cut_short_is_an_mvd_error_never_another(demos):
    data = demos["2on2"][0]
    rng = np.random.default_rng(1)
    errors = 0
    cuts = rng.integers(1, 200_000, 16).tolist() + [len(data) - 3]
    for cut in cuts:
        try:
            parse_mvd(data[:cut])
        except MvdError as exc:
            assert 0 <= exc.offset <= cut
            errors += 1
    assert errors >= len(cuts) - 2  # a cut on a block's end is a shorter demo


def test_the_cli_writes_a_match_file_that_reads_back_equal(demos, tmp_path, capsys):
    out = tmp_path / "m.npz"
    assert main(["import-match", str(DATA / DEMOS["1on1"]), "--out", str(out)]) == 0
    printed = json.loads(capsys.readouterr().out)
    expected = demos["1on1"][2].match
    assert printed["players"] == [{"name": "mushi", "team": 0}, {"name": "Milton", "team": 1}]
    assert printed["kills"] == len(expected.events) and printed["frames"] == len(expected.time_s)
    loaded = load_match(out)
    assert loaded.players == expected.players and loaded.level == expected.level
    for field in ("time_s", "positions_world", "rotations_xyzw", "alive", "stats"):
        np.testing.assert_array_equal(getattr(loaded, field), getattr(expected, field))
    assert [e.as_json() for e in loaded.events] == [e.as_json() for e in expected.events]


def test_the_cli_answers_bad_input_with_status_2_and_no_traceback(tmp_path, capsys):
    junk = tmp_path / "junk.mvd"
    junk.write_bytes(b"\x05\x06\xff\xff\xff\x7f")
    assert main(["import-match", str(junk), "--out", str(tmp_path / "m.npz")]) == 2
    err = capsys.readouterr().err
    assert f"{junk}: offset 0: not an MVD demo (it ends at byte 6, before its first message" in err and "Traceback" not in err
    assert main(["import-match", str(tmp_path / "missing.mvd.gz"), "--out", str(tmp_path / "m.npz")]) == 2
