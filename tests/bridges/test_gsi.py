"""bridges/gsi.py: the recorded observer payload parsed whole; what is not a payload refused."""

from __future__ import annotations

import json

import numpy as np
import pytest

from camdirector.bridges.gsi import GsiPayloadError, parse_payload
from tests.bridges.gsi_payloads import MIRAGE, mirage_sequence


def test_the_recorded_payload_has_every_player_with_position_and_facing():
    payload = parse_payload(MIRAGE.read_bytes())
    assert payload.timestamp_s == 1596015822 and payload.map_name == "workshop/2126169449/de_mirage"
    assert payload.round == 9 and payload.spectated == "76561198074613011"
    assert len(payload.players) == 10
    assert sorted(p.observer_slot for p in payload.players) == list(range(10))
    assert {p.team for p in payload.players} == {"T", "CT"}
    by_id = {p.steamid: p for p in payload.players}
    muminek = by_id["76561199031036917"]
    assert muminek.name == "Muminek" and muminek.team == "CT" and muminek.health == 39 and muminek.kills == 11
    np.testing.assert_allclose(muminek.position_units, [218.35, -1529.35, -175.97])
    np.testing.assert_allclose(muminek.forward, [-0.65, -0.76, -0.02])
    assert by_id["76561198097954759"].name == "♧♛𝐋𝔼Ǻ𝕄♛♧"  # names as the game sent them
    assert sum(p.health == 0 for p in payload.players) == 7


def test_the_state_before_differs_where_previously_says():
    before, now = (parse_payload(json.dumps(p).encode()) for p in mirage_sequence("t"))
    moved = {p.steamid for p, q in zip(before.players, now.players) if not np.array_equal(p.position_units, q.position_units)}
    assert moved == {"76561199031036917", "76561198981246981", "76561198074613011"}
    assert before.token == "t"


@pytest.mark.parametrize(
    "body, where",
    [
        (b"{not json", "not JSON"),
        (b"[1, 2]", "not a JSON object"),
        (b'{"allplayers": {"1": {"team": "X"}}}', "neither 'T' nor 'CT'"),
        (b'{"allplayers": {"1": {"team": "T", "position": "1, 2"}}}', "not three finite numbers"),
        (b'{"allplayers": {"1": {"team": "T", "position": "1, nan, 2"}}}', "not three finite numbers"),
        (b'{"allplayers": {"1": {"team": "T", "state": {"health": "full"}}}}', "is not a number"),
        (b'{"auth": {"token": 5}}', "auth.token"),
        (b"\xff\xfe", "not JSON"),
    ],
)
def test_what_is_not_a_payload_is_refused_with_where(body, where):
    with pytest.raises(GsiPayloadError, match=where):
        parse_payload(body)
