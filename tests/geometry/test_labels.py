"""Name labels over players (geometry/labels.py): drawn just above the projected head, in the team
colour's bar and the text's box, nowhere else; none for a head behind the camera, outside the
picture or without a name; the nearest drawn last."""

from __future__ import annotations

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens, project_to_screen
from camdirector.geometry.labels import BAR_PX, GAP_PX, draw_labels

LENS = Lens(aspect=16 / 9)
POSE = CameraPose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), LENS.vertical_fov_deg)  # looks down -Z
WIDTH, HEIGHT = 320, 180
GREY = 90
RED = np.array([200, 30, 30], dtype=np.uint8)


def blank() -> np.ndarray:
    return np.full((HEIGHT, WIDTH, 3), GREY, dtype=np.uint8)


def head_px(head_world) -> tuple[int, int]:
    x, y = project_to_screen(POSE, LENS, np.array([head_world]))[0]
    return round((x + 1) * 0.5 * (WIDTH - 1)), round((1 - y) * 0.5 * (HEIGHT - 1))


def test_a_label_sits_just_above_the_head_and_changes_nothing_else():
    head = [1.0, 0.5, -8.0]
    picture, placed = draw_labels(blank(), POSE, LENS, np.array([head]), ["<b>x</b>"], RED[None])
    x, y = head_px(head)
    assert [(p.text, p.centre_x_px, p.bottom_y_px) for p in placed] == [("<b>x</b>", x, y - GAP_PX)]
    changed = np.argwhere(np.any(picture != GREY, axis=2))
    rows, cols = changed[:, 0], changed[:, 1]
    assert rows.max() == y - GAP_PX - 1 and rows.min() < y - GAP_PX - 10  # a box of text over the bar
    assert abs(0.5 * (cols.min() + cols.max()) - x) <= 1  # centred on the head
    assert np.all(picture[y - GAP_PX - BAR_PX : y - GAP_PX, x] == RED)  # the team's bar under it
    assert np.any(picture[rows, cols].max(axis=1) > 200)  # light text on the dark box


def test_no_label_behind_the_camera_outside_the_picture_or_without_a_name():
    heads = np.array([[0.0, 0.5, 5.0], [40.0, 0.5, -5.0], [0.0, 0.5, -5.0]])  # behind, far right, unnamed
    picture, placed = draw_labels(blank(), POSE, LENS, heads, ["behind", "outside", ""], np.repeat(RED[None], 3, axis=0))
    assert placed == [] and np.all(picture == GREY)


def test_the_nearest_label_is_drawn_last_over_a_farther_one():
    heads = np.array([[0.0, 0.5, -4.0], [0.0, 0.5, -20.0]])  # the same line of sight, near then far
    colours = np.array([[200, 30, 30], [30, 30, 200]], dtype=np.uint8)
    _, placed = draw_labels(blank(), POSE, LENS, heads, ["near", "far"], colours)
    assert [p.text for p in placed] == ["far", "near"]
