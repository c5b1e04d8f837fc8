"""Resources are released with their session: wherever a session ends, its occlusion maps'
backend is closed, and a worker that creates, streams and closes 200 GL-backed sessions returns
to its memory and descriptors (issue 11, item 4)."""

from __future__ import annotations

import numpy as np
import pytest

import camdirector_client as cd
from camdirector.demo.client import session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.deploy.server_process import ServerProcess, worker_pids
from camdirector.errors import DirectorError
from camdirector.geometry.camera import Lens
from camdirector.geometry.toric_maps import embree, gl
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.dispatch import Dispatcher
from camdirector.worker.table import SessionTable
from load_tests.soak import sample_process

SESSIONS = 200
FRAMES = 5
MAX_GROWTH_MB = 50.0


@pytest.fixture(scope="module")
def demo():
    """The demo scene's ANTICIPATION request (backend set per test) and FRAMES frame updates."""
    scene = build_demo_scene(seed=7, duration_s=1.0)
    ids = [scene.avatar.id, *[o.id for o in scene.dynamic_objects]]
    frames = []
    for i in range(FRAMES):
        transforms = scene.transforms_at(i / 60.0)
        frames.append(
            (
                i + 1,
                i / 60.0,
                cd.pack_states(
                    ids,
                    np.stack([transforms[k].position_world for k in ids]),
                    np.stack([transforms[k].rotation_xyzw for k in ids]),
                ),
            )
        )
    return session_request(scene, Lens(), visibility=cd.pb.ANTICIPATION), frames


def _request(demo, backend: int, record: bool = False) -> pb.CreateSessionRequest:
    request = pb.CreateSessionRequest()
    request.CopyFrom(demo[0])
    request.style.map_backend = backend
    request.record = record
    return request


@pytest.fixture
def backends(monkeypatch):
    """Counts the map backends made and closed in this process: {"made": n, "closed": n}."""
    counts = {"made": 0, "closed": 0}
    for cls in (gl.GLMapBackend, embree.EmbreeMapBackend):
        made, closed = cls.__init__, cls.close

        def counting_init(self, *args, _made=made, **kwargs):
            _made(self, *args, **kwargs)
            counts["made"] += 1

        def counting_close(self, _closed=closed):
            counts["closed"] += 1
            _closed(self)

        monkeypatch.setattr(cls, "__init__", counting_init)
        monkeypatch.setattr(cls, "close", counting_close)
    return counts


def _frame(requests: Dispatcher, session_id: str, frame, time_s, packed) -> pb.CameraUpdate:
    ids, values = packed
    msg = pb.FrameUpdate(session_id=session_id, frame=frame, time_s=time_s, packed_ids=ids, packed_transforms=values)
    return pb.CameraUpdate.FromString(requests.handle_bytes("frame", session_id, msg.SerializeToString())[0])


@pytest.mark.parametrize("backend", [pb.MAP_BACKEND_GL, pb.MAP_BACKEND_EMBREE])
def test_every_way_a_session_ends_closes_its_map_backend(demo, backends, backend, tmp_path):
    table = SessionTable(ServerSettings(data_dir=str(tmp_path)))
    requests = Dispatcher(table)
    create = _request(demo, backend).SerializeToString()
    for session_id in ("closed", "reclaimed", "stopping-1", "stopping-2"):
        requests.handle_bytes("create", session_id, create)
        for frame in demo[1]:
            _frame(requests, session_id, *frame)
    assert backends == {"made": 4, "closed": 0}
    requests.handle_bytes("close", "closed", b"")  # CloseSession
    requests.handle_bytes("drop", "reclaimed", b"")  # the front's reaper, an idle session
    assert backends == {"made": 4, "closed": 2}
    table.close_all()  # the worker stops
    assert backends == {"made": 4, "closed": 4} and not table.held


def test_a_create_that_fails_after_the_maps_were_built_closes_them(demo, backends, tmp_path):
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("")  # the recordings folder cannot be made under a file
    table = SessionTable(ServerSettings(data_dir=str(blocker), checkpoint_store="off"))
    with pytest.raises(DirectorError) as err:
        Dispatcher(table).handle_bytes("create", "s", _request(demo, pb.MAP_BACKEND_GL, record=True).SerializeToString())
    assert err.value.code.name == "INTERNAL"
    assert backends == {"made": 1, "closed": 1} and not table.held


def test_recording_file_is_closed_with_its_session(demo, tmp_path):
    table = SessionTable(ServerSettings(data_dir=str(tmp_path)))
    requests = Dispatcher(table)
    reply = pb.CreateSessionResponse.FromString(
        requests.handle_bytes("create", "rec", _request(demo, pb.MAP_BACKEND_EMBREE, record=True).SerializeToString())[0]
    )
    recorder = table.held["rec"].recorder
    _frame(requests, "rec", *demo[1][0])
    table.close_all()
    assert recorder._file.closed and reply.recording_path


def test_200_gl_sessions_leave_the_worker_where_it_started(demo):
    """Created, given 5 frames and closed one after another on one worker: its resident memory
    grows by less than MAX_GROWTH_MB and its open descriptors come back to where they were. The
    first session is a warm-up: loading the GL driver and the kernel banks happens once."""
    request = _request(demo, pb.MAP_BACKEND_GL)
    with ServerProcess("--workers", "1", transports=("grpc",)) as server, cd.connect(server.url("grpc")) as client:
        (worker,) = worker_pids(server.proc.pid)

        def one_session() -> list[pb.CameraUpdate]:
            with client.create_session(request) as session:
                return [session.frame(frame, time_s, packed=packed) for frame, time_s, packed in demo[1]]

        one_session()
        before = sample_process(worker)
        last = [one_session() for _ in range(SESSIONS)][-1]
        after = sample_process(worker)
    assert any("projection" in u.diagnostics.stage_ms for u in last)  # the GL backend computed maps
    assert after.rss_mb - before.rss_mb < MAX_GROWTH_MB, (before, after)
    assert after.open_fds == before.open_fds, (before, after)
