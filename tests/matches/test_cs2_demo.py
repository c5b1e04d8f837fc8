"""matches/cs2_demo.py: CS2 demos into match files.

Hand-built demoparser2 tables pin the conversion (players, teams, late joiners, kills, bombs), the
real demos of tests/data/real_matches/cs2/ (SOURCES.md) go through demoparser2 end to end, and bad
files must end in Cs2DemoError, never in a crash."""

from __future__ import annotations

import gzip
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from camdirector.evaluation.match.match_file import load_match, save_match
from camdirector.geometry.transforms import quat_rotate
from camdirector.matches.cs2_demo import (
    ITEM_DEFUSER,
    ITEM_HELMET,
    M_PER_UNIT,
    TICK_PROPS,
    Cs2DemoError,
    check_demo_file,
    import_cs2_demo,
    match_from_tables,
    parse_demo_tables,
    source_points_to_world,
    view_rotation,
)
from tests.evaluation.match.test_match_file import assert_stands_and_aims

CS2_DEMOS = Path(__file__).resolve().parents[1] / "data" / "real_matches" / "cs2"
REAL_DEMOS = sorted(CS2_DEMOS.glob("*.dem.gz"))
# de_dust2's radar (the game's resource/overviews/de_dust2.txt: pos_x -2476, pos_y 3239, scale 4.4
# over 1024 pixels) covers the playable map: X -2476..2030, Y -1267..3239 units.
DUST2_BOX_UNITS = ((-2476.0, 2029.6), (-1266.6, 3239.0))
# What the two shipped demos hold (SOURCES.md): the player's side, origin (units), pitch and yaw.
SHIPPED = {
    "14155.dem.gz": (1, (160.12274169921875, 2369.67626953125, -119.918701171875), 0.0, 23.999969482421875, 161),
    "14160.dem.gz": (0, (-980.0, -754.0, 120.1812515258789), 0.0, -147.50003051757812, 156),
}


def _forward(pitch_deg: float, yaw_deg: float) -> np.ndarray:
    return quat_rotate(view_rotation(np.array(pitch_deg), np.array(yaw_deg)), np.array([0.0, 0.0, 1.0]))


def _up(pitch_deg: float, yaw_deg: float) -> np.ndarray:
    return quat_rotate(view_rotation(np.array(pitch_deg), np.array(yaw_deg)), np.array([0.0, 1.0, 0.0]))


@pytest.mark.parametrize(
    ("pitch", "yaw", "world"),
    [
        (0.0, 0.0, (1.0, 0.0, 0.0)),  # Source +X
        (0.0, 90.0, (0.0, 0.0, -1.0)),  # Source +Y is world -Z
        (0.0, 180.0, (-1.0, 0.0, 0.0)),
        (0.0, -90.0, (0.0, 0.0, 1.0)),
        (89.0, 0.0, (np.cos(np.radians(89.0)), -np.sin(np.radians(89.0)), 0.0)),  # positive pitch looks down
        (-45.0, 180.0, (-np.sqrt(0.5), np.sqrt(0.5), 0.0)),
    ],
)
def test_source_view_angles_turn_local_z_onto_the_view(pitch, yaw, world):
    np.testing.assert_allclose(_forward(pitch, yaw), world, atol=1e-12)
    if abs(pitch) < 60:
        assert _up(pitch, yaw)[1] > 0.5  # no roll: the head stays up


def test_source_units_are_inches_and_z_up_becomes_y_up():
    np.testing.assert_allclose(source_points_to_world(np.array([0.0, 0.0, 72.0])), [0.0, 1.8288, 0.0])
    np.testing.assert_allclose(source_points_to_world(np.array([[100.0, 200.0, 0.0]])), [[2.54, 0.0, -5.08]])
    assert M_PER_UNIT == 0.0254


# --- hand-built demoparser2 tables -------------------------------------------------------------


def _ticks(rows: list[dict]) -> dict[str, np.ndarray]:
    """parse_ticks' columns from rows of (tick, steamid, name, team, x, y, z, ...); the props a
    row leaves out take a living, unarmed player's values."""
    defaults = {
        "X": 0.0,
        "Y": 0.0,
        "Z": 0.0,
        "pitch": 0.0,
        "yaw": 0.0,
        "is_alive": True,
        "health": 100,
        "armor_value": 0,
        "kills_total": 0,
        "has_helmet": False,
        "has_defuser": False,
    }
    full = [{**defaults, **row} for row in rows]
    return {name: np.array([row[name] for row in full]) for name in ("tick", "steamid", "name", *TICK_PROPS)}


def _events(rows: list[dict]) -> dict[str, np.ndarray]:
    names = sorted({k for row in rows for k in row})
    return {name: np.array([row.get(name) for row in rows], dtype=object) for name in names}


ALICE, BOB, CAROL, DAVE = "76561190000000001", "76561190000000002", "76561190000000003", "76561190000000004"


def _two_teams(last_tick: int = 8) -> list[dict]:
    """Alice (T) and Bob (CT) at every tick 1..last_tick, a spectator at every tick, Carol (T)
    joining at tick 5, and Dave (CT) leaving after tick 3."""
    rows = []
    for t in range(1, last_tick + 1):
        rows.append(
            {
                "tick": t,
                "steamid": int(ALICE),
                "name": "alice",
                "team_num": 2,
                "X": 10.0 * t,
                "yaw": 90.0,
                "kills_total": 1 if t >= 4 else 0,
                "armor_value": 100,
                "has_helmet": True,
            }
        )
        rows.append(
            {
                "tick": t,
                "steamid": int(BOB),
                "name": "bob",
                "team_num": 3,
                "Y": 100.0,
                "is_alive": t < 4,
                "health": 100 if t < 4 else 0,
                "has_defuser": True,
            }
        )
        rows.append({"tick": t, "steamid": 76561190000000009, "name": "caster", "team_num": 1})
        if t >= 5:
            rows.append({"tick": t, "steamid": int(CAROL), "name": "carol", "team_num": 2, "X": -50.0})
        if t <= 3:
            rows.append({"tick": t, "steamid": int(DAVE), "name": "dave", "team_num": 3, "Z": 64.0, "kills_total": 2})
    return rows


def test_players_are_who_played_on_t_or_ct_in_order_of_appearance():
    match = match_from_tables(_ticks(_two_teams()), {}, {}, level="de_test")
    assert [(p.name, p.team) for p in match.players] == [("alice", 0), ("bob", 1), ("dave", 1), ("carol", 0)]
    assert match.level == "de_test" and len(match.time_s) == 8
    np.testing.assert_allclose(match.time_s, np.arange(1, 9) / 64.0)
    np.testing.assert_allclose(match.players[0].height_m, 72 * 0.0254)


def test_a_player_looking_down_stands_upright_and_keeps_its_aim():
    rows = [{"tick": t, "steamid": int(ALICE), "name": "alice", "team_num": 2, "pitch": 60.0, "yaw": 30.0} for t in (1, 2)]
    match = match_from_tables(_ticks(rows), {}, {}, level="de_test")
    for frame in range(2):
        assert_stands_and_aims(match, frame, 0, 60.0, 30.0)
    assert match.aim_pitch_deg.tolist() == [[60.0], [60.0]]


def test_feet_facing_alive_and_stats_per_frame():
    match = match_from_tables(_ticks(_two_teams()), {}, {}, level="de_test")
    alice, bob, dave, carol = range(4)
    np.testing.assert_allclose(match.positions_world[:, alice, 0], 10.0 * np.arange(1, 9) * 0.0254)
    np.testing.assert_allclose(match.positions_world[0, bob], [0.0, 0.0, -100.0 * 0.0254])
    np.testing.assert_allclose(match.rotations_xyzw[0, alice], view_rotation(np.array(0.0), np.array(90.0)))
    assert match.alive[:, alice].all()
    assert match.alive[:3, bob].all() and not match.alive[3:, bob].any()  # died at tick 4
    assert match.stats[0, alice].tolist() == [100, 100, ITEM_HELMET, 0]
    assert match.stats[5, alice, 3] == 1  # a frag from tick 4
    assert match.stats[0, bob, 2] == ITEM_DEFUSER and match.stats[5, bob, 0] == 0


def test_late_joiners_and_leavers_are_absent_and_held_in_place():
    match = match_from_tables(_ticks(_two_teams()), {}, {}, level="de_test")
    dave, carol = 2, 3
    assert match.alive[:3, dave].all() and not match.alive[3:, dave].any()
    assert not match.alive[:4, carol].any() and match.alive[4:, carol].all()
    np.testing.assert_allclose(match.positions_world[:, dave], np.tile([0.0, 64.0 * 0.0254, 0.0], (8, 1)))
    np.testing.assert_allclose(match.positions_world[:, carol, 0], -50.0 * 0.0254)  # before joining: where it joins
    assert match.stats[7, dave].tolist() == [0, 0, 0, 2]  # gone: frags held, the rest 0
    assert match.stats[0, carol].tolist() == [0, 0, 0, 0]


def test_a_team_is_a_roster_so_it_survives_the_half_time_swap():
    rows = [{"tick": t, "steamid": int(ALICE), "name": "alice", "team_num": 2 if t <= 2 else 3} for t in range(1, 5)]
    rows += [{"tick": t, "steamid": int(BOB), "name": "bob", "team_num": 3 if t <= 2 else 2} for t in range(1, 5)]
    match = match_from_tables(_ticks(rows), {}, {}, level="de_test")
    assert [p.team for p in match.players] == [0, 1]
    assert match.alive.all()


def test_bots_are_told_apart_by_name():
    rows = [{"tick": 1, "steamid": 0, "name": name, "team_num": team} for name, team in (("BOT Al", 2), ("BOT Bo", 3))]
    match = match_from_tables(_ticks(rows), {}, {}, level="de_test")
    assert [p.name for p in match.players] == ["BOT Al", "BOT Bo"]


def test_rate_hz_takes_every_nth_tick_and_refuses_more_than_the_tick_rate():
    match = match_from_tables(_ticks(_two_teams(last_tick=16)), {}, {}, level="de_test", rate_hz=16.0)
    np.testing.assert_allclose(match.time_s * 64.0, [1, 5, 9, 13])
    with pytest.raises(ValueError, match="rate_hz"):
        match_from_tables(_ticks(_two_teams()), {}, {}, level="de_test", rate_hz=128.0)


def test_a_demo_without_players_on_a_team_is_refused():
    rows = [{"tick": 1, "steamid": 7, "name": "caster", "team_num": 1}]
    with pytest.raises(ValueError, match="no player is on T or CT"):
        match_from_tables(_ticks(rows), {}, {}, level="de_test")


def _death(tick, victim, attacker, weapon, headshot=False, at=(0.0, 0.0, 0.0)):
    (victim_id, victim_name), attacker = victim, attacker or (None, None)
    return {
        "tick": tick,
        "user_steamid": victim_id,
        "user_name": victim_name,
        "attacker_steamid": attacker[0],
        "attacker_name": attacker[1],
        "weapon": weapon,
        "headshot": headshot,
        "user_X": at[0],
        "user_Y": at[1],
        "user_Z": at[2],
    }


def test_every_player_death_is_a_kill_with_weapon_headshot_and_place():
    alice, bob, dave, carol = (ALICE, "alice"), (BOB, "bob"), (DAVE, "dave"), (CAROL, "carol")
    deaths = _events(
        [
            _death(4, bob, alice, "ak47", headshot=True, at=(0.0, 100.0, 0.0)),
            _death(6, carol, None, "world"),
            _death(7, carol, carol, "hegrenade"),
            _death(3, dave, (DAVE, "dave"), "inferno"),
            _death(8, carol, alice, "glock"),
            _death(99, dave, alice, "knife"),  # after the last frame: at the last frame
        ]
    )
    match = match_from_tables(_ticks(_two_teams()), deaths, {}, level="de_test")
    kills = [(e.actor_id, e.other_actor_id, e.label, round(e.time_s * 64)) for e in match.events]
    assert kills == [
        ("p02", "p02", "suicide:inferno", 3),
        ("p00", "p01", "ak47 headshot", 4),
        ("p03", "p03", "world:world", 6),
        ("p03", "p03", "suicide:hegrenade", 7),
        ("p00", "p03", "teamkill:glock", 8),
        ("p00", "p02", "knife", 8),
    ]
    assert all(e.kind == "kill" for e in match.events)
    np.testing.assert_allclose(match.events[1].position_world, [0.0, 0.0, -100.0 * 0.0254])


def test_bomb_events_are_objectives_at_the_bomb():
    planted = _events(
        [{"tick": 2, "user_steamid": ALICE, "user_name": "alice", "user_X": 500.0, "user_Y": 600.0, "user_Z": 10.0}]
    )
    defused = _events([{"tick": 5, "user_steamid": BOB, "user_name": "bob", "user_X": 510.0, "user_Y": 590.0, "user_Z": 10.0}])
    exploded = _events([{"tick": 7, "user_steamid": None, "user_name": None, "user_X": None, "user_Y": None, "user_Z": None}])
    bombs = {"bomb_planted": planted, "bomb_defused": defused, "bomb_exploded": exploded}
    match = match_from_tables(_ticks(_two_teams()), {}, bombs, level="de_test")
    bomb_world = source_points_to_world(np.array([500.0, 600.0, 10.0]))
    assert [(e.kind, e.actor_id, e.label) for e in match.events] == [
        ("objective", "p00", "bomb planted"),
        ("objective", "p01", "bomb defused"),
        ("objective", "p00", "bomb exploded"),
    ]
    for event in match.events:
        np.testing.assert_allclose(event.position_world, bomb_world)


# --- bad files ---------------------------------------------------------------------------------


def _real_demo(tmp_path: Path, name: str) -> Path:
    path = tmp_path / name.removesuffix(".gz")
    path.write_bytes(gzip.decompress((CS2_DEMOS / name).read_bytes()))
    return path


def test_a_truncated_demo_is_refused_with_the_offsets(tmp_path):
    whole = _real_demo(tmp_path, "14160.dem.gz")
    cut = tmp_path / "cut.dem"
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
    with pytest.raises(
        Cs2DemoError,
        match=r"cut\.dem: truncated CS2 demo: it ends at byte 103945, but its header "
        r"places the closing file info at byte 207875",
    ):
        import_cs2_demo(cut)
    header_only = tmp_path / "header.dem"
    header_only.write_bytes(whole.read_bytes()[:10])
    with pytest.raises(Cs2DemoError, match="shorter than its 16-byte header"):
        import_cs2_demo(header_only)


def test_random_bytes_and_other_files_are_refused(tmp_path):
    noise = tmp_path / "noise.dem"
    noise.write_bytes(np.random.default_rng(7).bytes(4096))
    with pytest.raises(Cs2DemoError, match="noise.dem: not a CS2 demo"):
        import_cs2_demo(noise)
    source1 = tmp_path / "csgo.dem"
    source1.write_bytes(b"HL2DEMO\x00" + bytes(2000))
    with pytest.raises(Cs2DemoError, match="Source 1"):
        import_cs2_demo(source1)
    with pytest.raises(Cs2DemoError, match="cannot read the demo"):
        import_cs2_demo(tmp_path / "missing.dem")


def test_a_cs2_header_over_random_bytes_is_refused_by_demoparser2(tmp_path):
    body = np.random.default_rng(3).bytes(3000)
    fake = tmp_path / "fake.dem"
    fake.write_bytes(b"PBDEMS2\x00" + (3004).to_bytes(4, "little") + (3000).to_bytes(4, "little") + body)
    check_demo_file(fake)  # the header alone looks whole
    with pytest.raises(Cs2DemoError, match="fake.dem: demoparser2 cannot read this demo"):
        import_cs2_demo(fake)


def test_a_panic_inside_demoparser2_is_caught(tmp_path):
    # Shorter than the header: demoparser2 0.42.0 panics slicing it (import_cs2_demo checks first).
    stub = tmp_path / "stub.dem"
    stub.write_bytes(b"PBDEMS2\x00")
    with pytest.raises(Cs2DemoError, match=r"stub.dem: demoparser2 failed on this demo \(panic: range end index"):
        parse_demo_tables(stub)


def test_without_demoparser2_the_error_says_how_to_install_it(tmp_path):
    demo = _real_demo(tmp_path, "14160.dem.gz")
    script = (
        "import sys; sys.modules['demoparser2'] = None\n"
        "from camdirector.matches.cs2_demo import Cs2SupportMissing, import_cs2_demo\n"
        "try:\n"
        "    import_cs2_demo(sys.argv[1])\n"
        "except Cs2SupportMissing as exc:\n"
        "    print('MISSING', exc)\n"
    )
    result = subprocess.run([sys.executable, "-c", script, str(demo)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "MISSING reading CS2 demos needs the demoparser2 package: pip install 'camdirector[cs2]'" in result.stdout


# --- the real demos ----------------------------------------------------------------------------


def _death_count(path: Path) -> int:
    from demoparser2 import DemoParser

    deaths = DemoParser(str(path)).parse_event("player_death")
    return len(deaths)


def _check_plausible(match, path: Path) -> None:
    """What every real CS2 match must satisfy: kills = the demo's deaths, feet inside the map, speeds
    a runner's, and nobody alive just after being killed."""
    kills = [e for e in match.events if e.kind == "kill"]
    assert len(kills) == _death_count(path)
    feet_units = match.positions_world / M_PER_UNIT
    assert np.all(np.abs(feet_units) < 16384.0)  # Source 2's world limit
    if match.level == "de_dust2":
        (x0, x1), (y0, y1) = DUST2_BOX_UNITS
        on = match.alive
        assert np.all((feet_units[..., 0][on] >= x0) & (feet_units[..., 0][on] <= x1))
        assert np.all((-feet_units[..., 2][on] >= y0) & (-feet_units[..., 2][on] <= y1))
    both_alive = match.alive[1:] & match.alive[:-1]
    speed = np.linalg.norm(np.diff(match.positions_world, axis=0), axis=-1) / np.diff(match.time_s)[:, None]
    assert np.all(speed[both_alive] < 15.0)  # 6.35 m/s running; falls and boosts stay under 15
    index = match.player_index()
    for kill in kills:
        after = np.searchsorted(match.time_s, kill.time_s + 0.5)
        assert after >= len(match.time_s) or not match.alive[after, index[kill.other_actor_id]]


@pytest.mark.parametrize("name", [p.name for p in REAL_DEMOS])
def test_a_real_demo_imports(tmp_path, name):
    path = _real_demo(tmp_path, name)
    match = import_cs2_demo(path)
    _check_plausible(match, path)
    assert match.level == "de_dust2"
    if name in SHIPPED:
        team, origin, pitch, yaw, n_ticks = SHIPPED[name]
        assert [(p.name, p.team) for p in match.players] == [("Partridge", team)]
        np.testing.assert_allclose(match.time_s, np.arange(1, n_ticks + 1) / 64.0)
        np.testing.assert_allclose(match.positions_world[:, 0], np.tile(source_points_to_world(np.array(origin)), (n_ticks, 1)))
        np.testing.assert_allclose(match.rotations_xyzw[0, 0], view_rotation(np.array(pitch), np.array(yaw)))
        assert match.alive.all() and match.events == []
        assert match.stats[0, 0].tolist() == [100, 0, 0, 0]
    save_match(match, tmp_path / "match.npz")
    again = load_match(tmp_path / "match.npz")
    assert again.players == match.players
    np.testing.assert_array_equal(again.stats, match.stats)
    np.testing.assert_array_equal(again.positions_world, match.positions_world)
    assert import_cs2_demo(path, level="dust2_obj", rate_hz=8.0).level == "dust2_obj"


def test_a_real_match_demo_has_ten_players_in_two_teams(tmp_path):
    matches = [(p, import_cs2_demo(path)) for p in REAL_DEMOS for path in [_real_demo(tmp_path, p.name)]]
    full = [(p, m) for p, m in matches if len(m.players) >= 10]
    if not full:
        pytest.skip(
            "no CS2 demo of a whole match is shipped: none public, small and licensed was found "
            "(tests/data/real_matches/cs2/SOURCES.md)"
        )
    for path, match in full:
        assert len(match.players) == 10, path
        assert sorted(p.team for p in match.players) == [0] * 5 + [1] * 5, path
        assert any(e.kind == "kill" for e in match.events), path
