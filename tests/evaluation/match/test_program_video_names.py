"""eval-match's video labels each living player it shows with its name (program_video.py): over
the player's projected head, the id where the game gave no name, none for the dead."""

from __future__ import annotations

import numpy as np

from camdirector.evaluation.match.match_file import MatchPlayer, MatchRecording
from camdirector.evaluation.match.program_video import VIDEO_SIZE_PX, label_players
from camdirector.geometry.camera import CameraPose, Lens, project_to_screen
from camdirector.geometry.labels import GAP_PX

LENS = Lens(aspect=VIDEO_SIZE_PX[0] / VIDEO_SIZE_PX[1])
POSE = CameraPose(np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0]), LENS.vertical_fov_deg)  # looks down -Z


def three_players(alive: list[bool]) -> MatchRecording:
    players = [
        MatchPlayer("p00", 0, 1.75, 0.5, name="<b>x</b>", team_name="red"),
        MatchPlayer("p01", 1, 1.75, 0.5),  # a bot: no name
        MatchPlayer("p02", 1, 1.75, 0.5, name="Åsa"),
    ]
    feet = np.array([[[-2.0, 0.0, -8.0], [2.0, 0.0, -8.0], [0.0, 0.0, -12.0]]])
    return MatchRecording(
        level="l",
        seed=0,
        rate_hz=30.0,
        players=players,
        time_s=np.array([0.0]),
        positions_world=feet,
        rotations_xyzw=np.tile([0.0, 0.0, 0.0, 1.0], (1, 3, 1)),
        alive=np.array([alive]),
        events=[],
    )


def test_each_living_player_is_labelled_over_its_head_by_name_or_id():
    match = three_players([True, True, False])
    width, height = VIDEO_SIZE_PX
    blank = np.zeros((height, width, 3), dtype=np.uint8)
    labelled, placed = label_players(blank, match, 0, POSE, LENS)
    heads = match.positions_world[0, :2] + [0.0, 1.75, 0.0]
    screen = project_to_screen(POSE, LENS, heads)
    expected = [
        (text, round((x + 1) * 0.5 * (width - 1)), round((1 - y) * 0.5 * (height - 1)) - GAP_PX)
        for text, (x, y) in zip(["<b>x</b>", "p01"], screen)
    ]
    assert sorted((p.text, p.centre_x_px, p.bottom_y_px) for p in placed) == sorted(expected)  # the dead Åsa: none
    assert np.count_nonzero(labelled) > 0 and not np.any(labelled[expected[0][2] + 1 :])  # nothing below the heads
    assert labelled.flags.writeable  # the video draws its top-view inset over it
