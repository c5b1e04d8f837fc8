"""The monitors label players with their names (render/snapshots.py's TargetLabel, drawn by
render/main.py): a MATCH player by its display name or else its id, another rig's target only
when it has a name; the label sits over the head of the target where the snapshot has it, and the
picture (a real render) differs from the same one unlabelled exactly above the target."""

from __future__ import annotations

import dataclasses
import io

import numpy as np
import pytest
from PIL import Image

from camdirector.geometry.camera import project_to_screen
from camdirector.infra.channels import ViewQuery, decode_view
from camdirector.render.main import Painter
from camdirector.render.snapshots import label_heads, render_job, scene_geometry
from camdirector.server_settings import ServerSettings
from camdirector.worker.table import SessionTable
from tests.service.test_match_sessions import match_request
from tests.service.wire_client import two_target_request, walk


@pytest.fixture
def table():
    t = SessionTable(ServerSettings(checkpoint_store="off"))
    yield t
    t.close_all()


def test_match_players_are_labelled_by_name_or_id_and_other_targets_only_by_name(table):
    request = match_request(0.0)
    request.targets[0].display_name = "<b>x</b>"
    table.create("m", request)
    labels = scene_geometry(table.held["m"].session).labels
    assert [label.text for label in labels] == ["<b>x</b>", *[t.id for t in request.targets[1:]]]
    named = two_target_request(seed=2)
    named.targets[1].display_name = "Bee"
    table.create("t", named)
    assert [(label.part_id, label.text) for label in scene_geometry(table.held["t"].session).labels] == [("target:b", "Bee")]


def test_a_label_is_over_the_head_where_the_snapshot_has_the_target(table):
    request = two_target_request(seed=2)
    request.targets[0].display_name = "Ay"
    table.create("s", request)
    for update in walk("s", 20):
        table.frame(update)
    session = table.held["s"].session
    (label,) = scene_geometry(session).labels
    mesh = session.targets[0].mesh.vertices
    assert label.head_local[1] == pytest.approx(mesh[:, 1].max())  # the top of the capsule
    job = render_job(session, ViewQuery())
    np.testing.assert_allclose(label_heads(job, (label,))[0], session.target_transforms[0].apply(label.head_local[None])[0])


def test_a_labelled_picture_differs_from_the_unlabelled_one_just_above_the_head(table):
    request = two_target_request(seed=2)
    request.targets[0].display_name = "Ay"
    table.create("s", request)
    for update in walk("s", 20):
        table.frame(update)
    session = table.held["s"].session
    geometry = scene_geometry(session)
    job = render_job(session, ViewQuery(image_format="png"))
    painter = Painter()
    try:
        painter.add_session("s", geometry)
        header, labelled = decode_view(painter.render(job))
        painter.add_session("s", dataclasses.replace(geometry, labels=()))
        bare_header, bare = decode_view(painter.render(job))
    finally:
        painter.close()
    assert header["labels"] == ["Ay"] and bare_header["labels"] == []
    a, b = (np.asarray(Image.open(io.BytesIO(image)).convert("RGB")) for image in (labelled, bare))
    changed = np.argwhere(np.any(a != b, axis=2))
    assert len(changed), "the label changed no pixel"
    (x, y), (width, height) = project_to_screen(job.pose, job.lens, label_heads(job, geometry.labels))[0], job.size_px
    head_col, head_row = (x + 1) * 0.5 * (width - 1), (1 - y) * 0.5 * (height - 1)
    assert changed[:, 0].max() < head_row  # all above the head
    assert changed[:, 1].min() <= head_col <= changed[:, 1].max()  # across it
