"""With `--workers 0` the front process holds the sessions, and the compiled edge computes a routed
session's frame on its own thread (WorkerPool.answer_inline, native/src/edge.rs's Host::Inline): no
hop to another process. A session whose rig is bound to the thread that made it (GL occlusion maps:
their EGL context is current there, CameraRig.thread_bound) is answered on the front's loop instead,
from the frame its style asks for GL on; either way it answers as on a server with a worker.
(tests/front/test_zmq_edge.py and test_grpc_edge.py run the rest of the edge's tests on such a
server too: fronts.SERVERS' "inline".)"""

from __future__ import annotations

import time

import pytest

from camdirector.deploy.server_process import ServerProcess
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.checkpoint_stores import open_store
from tests.front.fronts import edge_frames, without_timings
from tests.service import wire_client as wc

GL = pb.Style(visibility=pb.ANTICIPATION, map_backend=pb.MAP_BACKEND_GL)
NATIVE = pb.Style(visibility=pb.ANTICIPATION)


@pytest.fixture(scope="module")
def servers():
    started = {workers: ServerProcess("--workers", workers, transports=("zmq", "http")) for workers in ("0", "1")}
    yield started
    for server in started.values():
        server.stop()


def test_a_session_on_gl_maps_is_answered_on_the_loops_thread_and_as_with_a_worker(servers):
    cameras: dict[str, list[pb.CameraUpdate]] = {}
    answered: dict[str, list[float]] = {}
    for workers, server in servers.items():
        client = wc.ZmqRaw(server.zmq)
        session_id = client.call("CreateSession", wc.two_target_request(seed=5, style=NATIVE)).session_id
        counts = [edge_frames(server)]
        first = client.stream(list(wc.walk(session_id, 12)))
        counts.append(edge_frames(server))
        client.call("UpdateStyle", pb.UpdateStyleRequest(session_id=session_id, style=GL))
        second = client.stream(list(wc.walk(session_id, 12, start_frame=13)))
        counts.append(edge_frames(server))
        gl_session = client.call("CreateSession", wc.two_target_request(seed=6, style=GL)).session_id
        third = client.stream(list(wc.walk(gl_session, 12)))
        counts.append(edge_frames(server))
        assert any("projection" in u.diagnostics.stage_ms for u in second + third)  # the GL backend computed maps
        cameras[workers] = [without_timings(u) for u in first + second + third]
        answered[workers] = [b - a for a, b in zip(counts, counts[1:])]
        for session in (session_id, gl_session):
            client.call("CloseSession", pb.CloseSessionRequest(session_id=session))
        client.close()
    assert [u.frame for u in cameras["0"]] == [*range(1, 25), *range(1, 13)]
    assert cameras["0"] == cameras["1"]
    # the first frame goes through the front, which routes the session; on GL maps, a worker's
    # session is answered by the edge (its worker's thread made the context), the front's is not
    assert answered["1"] == [11, 12, 11]
    assert answered["0"] == [11, 0, 0]


def test_the_edges_thread_takes_a_snapshot_due_when_it_has_nothing_else_to_do():
    """The front's table leaves a snapshot due for an idle moment (WorkerPool.hand_inline_to); the
    edge's thread takes it when it is about to sleep (native/src/edge.rs, idle_moment), after the
    deferred maps of that session. With nothing calling the table's idle work, the snapshot would
    wait for the 20th input."""
    with ServerProcess("--workers", "0", "--checkpoint-every-frames", "10", transports=("zmq", "http")) as server:
        client = wc.ZmqRaw(server.zmq)
        session_id = client.call("CreateSession", wc.two_target_request(seed=5, style=NATIVE)).session_id
        assert len(client.stream(list(wc.walk(session_id, 12)))) == 12
        assert edge_frames(server) == 11  # all but the first, which routed the session
        store = open_store("", server.data_dir, keep_s=600.0)
        deadline = time.monotonic() + 10.0
        while (checkpoint := store.load(session_id)).seq < 10 and time.monotonic() < deadline:
            time.sleep(0.05)
        # taken in a moment after the 10th frame's answer, of the session as it was then
        assert checkpoint.seq >= 10 and checkpoint.seq + len(checkpoint.entries) == 12
        client.close()
