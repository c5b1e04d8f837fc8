"""Name labels over players in a rendered picture: the dashboard's monitors (render/main.py) and
`eval-match`'s video (evaluation/match/program_video.py) draw them the same way.

A label is its text on a dark box centred above the player's head, with a bar of the player's
team colour under it, so a viewer reads who is who and on which side. A head behind the camera or
outside the picture has no label (a label pinned to the edge would point at nobody); a player
behind a wall keeps its label, as game spectators' name tags do, so a caster sees who is about
to appear. Nearer players' labels are drawn last, over farther ones. The text is drawn as pixels,
never interpreted: a name from a game is untrusted text.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens, project_to_screen
from camdirector.geometry.transforms import quat_to_matrix

FONT_PX = 11  # the labels' text height, px: readable on a 320-px monitor and a 480-px video
PAD_PX = 2  # around the text inside its box, px
GAP_PX = 3  # between the head and the bottom of the label's team bar, px
BAR_PX = 2  # the team colour's bar under the box, px
TEXT_RGB = (255, 255, 255)
BOX_RGB = (24, 24, 28)


@dataclass(frozen=True)
class PlacedLabel:
    """A label as drawn: its text and where, in pixels (x right, y down, from the top left)."""

    text: str
    centre_x_px: int
    bottom_y_px: int  # the bar's bottom edge, GAP_PX above the head


@cache
def _font() -> Any:
    from PIL import ImageFont  # Pillow's own scalable font (FreeType), no system font needed

    return ImageFont.load_default(size=FONT_PX)


def draw_labels(
    pixels: np.ndarray,
    pose: CameraPose,
    lens: Lens,
    heads_world: np.ndarray,
    texts: Sequence[str],
    bar_rgb: np.ndarray,
) -> tuple[np.ndarray, list[PlacedLabel]]:
    """The picture pixels (h, w, 3) uint8, seen from pose with lens, with a label over each head
    (heads_world (n, 3) m, the top of each player) whose text is not empty; bar_rgb (n, 3) uint8
    each label's team colour. Returns a new picture and the labels drawn, nearest last."""
    from PIL import Image, ImageDraw

    if not any(texts):
        return pixels, []
    height, width = pixels.shape[:2]
    screen = project_to_screen(pose, lens, heads_world)
    depth_m = (heads_world - pose.position_world) @ -quat_to_matrix(pose.rotation_xyzw)[:, 2]  # along the view
    shown = [
        k
        for k, ((x, y), text) in enumerate(zip(screen.tolist(), texts))
        if text and np.isfinite(x) and abs(x) <= 1.0 and abs(y) <= 1.0
    ]
    shown.sort(key=lambda k: -depth_m[k])  # farthest first: the nearest label ends on top
    card = Image.fromarray(pixels, "RGB")
    draw = ImageDraw.Draw(card)
    placed = []
    for k in shown:
        x, y = screen[k]
        centre_x, head_y = round((x + 1.0) * 0.5 * (width - 1)), round((1.0 - y) * 0.5 * (height - 1))
        left, top, right, bottom = draw.textbbox((0, 0), texts[k], font=_font())
        box_w, box_h = right - left + 2 * PAD_PX, bottom - top + 2 * PAD_PX
        bar_bottom = head_y - GAP_PX
        x0, y0 = centre_x - box_w // 2, bar_bottom - BAR_PX - box_h
        draw.rectangle((x0, y0, x0 + box_w - 1, y0 + box_h - 1), fill=BOX_RGB)
        draw.rectangle((x0, y0 + box_h, x0 + box_w - 1, bar_bottom - 1), fill=tuple(int(c) for c in bar_rgb[k]))
        draw.text((x0 + PAD_PX - left, y0 + PAD_PX - top), texts[k], fill=TEXT_RGB, font=_font())
        placed.append(PlacedLabel(texts[k], centre_x, bar_bottom))
    return np.array(card), placed  # a writable copy: callers draw over it (the video's inset)
