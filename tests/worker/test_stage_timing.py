"""Stage times come from the session's injected clock, lapped by one helper: with a clock that
moves 1 ms per reading every stage of a frame reads exactly its number of laps, and the keys are
the ones on the wire (pipeline/stages.py)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import camdirector_client as cd
from camdirector.demo.client import session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.geometry.camera import Lens
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.table import SessionTable


def _stage_ms(visibility: int, frames: int, tmp_path) -> list[dict[str, float]]:
    ticks = itertools.count()
    table = SessionTable(ServerSettings(data_dir=str(tmp_path)), clock=lambda: next(ticks) * 1e-3)
    scene = build_demo_scene(seed=7, duration_s=1.0)
    request = session_request(scene, Lens(), visibility=visibility)
    request.style.map_backend = pb.MAP_BACKEND_EMBREE
    table.create("s", request)
    ids = [scene.avatar.id, *[o.id for o in scene.dynamic_objects]]
    out = []
    for i in range(frames):
        transforms = scene.transforms_at(i / 60.0)
        packed_ids, packed = cd.pack_states(
            ids, np.stack([transforms[k].position_world for k in ids]), np.stack([transforms[k].rotation_xyzw for k in ids])
        )
        reply = table.frame(
            pb.FrameUpdate(session_id="s", frame=i + 1, time_s=i / 60.0, packed_ids=packed_ids, packed_transforms=packed)
        )
        out.append(dict(reply.diagnostics.stage_ms))
    table.close_all()
    return out


def test_framing_only_laps_each_stage_once(tmp_path):
    for stage_ms in _stage_ms(pb.FRAMING_ONLY, 3, tmp_path):
        assert stage_ms == pytest.approx({"ingest": 1.0, "framing": 1.0, "motion": 1.0, "visibility": 1.0})


def test_map_modes_lap_motion_around_the_map_stages(tmp_path):
    """MOTION is lapped before the maps' update and after it, PROJECTION and AMAP only on frames
    that compute maps (AMAP twice there: predicting, then storing into the A-map); no time is
    counted twice."""
    frames = _stage_ms(pb.ANTICIPATION, 12, tmp_path)
    with_maps = [f for f in frames if "projection" in f]
    without = [f for f in frames if "projection" not in f]
    assert with_maps and without
    for stage_ms in with_maps:
        assert stage_ms == pytest.approx(
            {"ingest": 1.0, "framing": 1.0, "motion": 2.0, "projection": 1.0, "amap": 2.0, "visibility": 1.0}
        )
    for stage_ms in without:
        assert stage_ms == pytest.approx({"ingest": 1.0, "framing": 1.0, "motion": 2.0, "visibility": 1.0})
