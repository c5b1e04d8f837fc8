"""The cluster on one machine, through HAProxy (deploy/cluster.py, deploy/haproxy.py): one route key
keeps every call of a session on one node, keys spread over the nodes where HAProxy's ring puts
them (load_tests/ring_sim.py's model), a node that joins breaks no live stream, and a node that
dies is marked down within seconds, its keys going to the others; with no node left, UNAVAILABLE.
The tests run in order on one cluster: the join adds node-3, the last test kills nodes."""
from __future__ import annotations

import threading
import time
import urllib.request

import grpc
import pytest

from camdirector.deploy.haproxy import GRPC_BACKEND, ROUTE_HEADER
from load_tests.ring_sim import Ring, key_hashes
from tests.deploy.conftest import new_keys, node_of, route, sessions_by_node
from tests.service import wire_client as wc


def create(stub, key: str) -> str:
    return stub.CreateSession(wc.two_target_request(), metadata=route(key), timeout=30).session_id


def predicted(cluster, keys: list[str], without: tuple[str, ...] = ()) -> list[str]:
    """The node HAProxy's ring gives each key, from the model, over the nodes not in `without`."""
    weight = cluster.settings.balancer.weight
    ring = Ring({n.server_id: weight for n in cluster.nodes if n.node_id not in without})
    return [f"node-{sid}" for sid in ring.owner(key_hashes(keys))]


def test_every_call_with_one_route_key_lands_on_one_node(cluster, stub):
    (key,) = new_keys(1)
    session_id = create(stub, key)
    for update in wc.walk(session_id, 20):
        stub.Frame(update, metadata=route(key), timeout=30)
    replies = list(stub.StreamFrames(wc.walk(session_id, 30, start_frame=21), metadata=route(key), timeout=30))
    assert [r.frame for r in replies] == list(range(21, 51))
    held = sessions_by_node(cluster)
    (listing,) = [s for s in _listing(cluster, node_of(held, session_id)) if s["session_id"] == session_id]
    assert listing["frames"] == 50  # every frame answered by the node that holds it


def _listing(cluster, node_id: str) -> list[dict]:
    import json
    (node,) = [n for n in cluster.nodes if n.node_id == node_id]
    with urllib.request.urlopen(f"http://{node.http}/v1/sessions", timeout=5) as reply:
        return json.load(reply)["sessions"]


def test_keys_spread_over_the_nodes_where_the_ring_model_puts_them(cluster, stub):
    keys = new_keys(24)
    sessions = [create(stub, key) for key in keys]
    held = sessions_by_node(cluster)
    actual = [node_of(held, sid) for sid in sessions]
    assert set(actual) == {"node-1", "node-2"}
    assert actual == predicted(cluster, keys)  # ring_sim models HAProxy's placement exactly


def test_rest_calls_with_the_route_key_reach_the_node_of_the_session(cluster, stub):
    keys = new_keys(6)
    for key, session_id in zip(keys, [create(stub, key) for key in keys]):
        request = urllib.request.Request(f"http://{cluster.http}/v1/sessions/{session_id}", headers={ROUTE_HEADER: key})
        with urllib.request.urlopen(request, timeout=5) as reply:
            assert reply.status == 200


def test_a_level_added_through_one_node_directs_a_session_on_the_other(cluster):
    """Job and level records in PostgreSQL, artifacts in the shared folder: the level job of one
    node's REST API is seen by the other, which lists the level and directs a TRACKS session on it."""
    import httpx

    from tests.precompute.tracks.tiny_levels import corridor
    from tests.service.tracks_sessions import actor_frames, check_directed, corridor_walk, obj_text, tracks_request

    first, second = (f"http://{node.http}" for node in cluster.nodes[:2])
    posted = httpx.post(f"{first}/v1/levels", data={"name": "corridor"},
                        files={"level": ("level.obj", obj_text(corridor()))}, timeout=30)
    assert posted.status_code == 202, posted.text
    job = posted.json()["id"]
    deadline = time.monotonic() + 120
    while (status := httpx.get(f"{first}/v1/level-jobs/{job}", timeout=10).json()["status"]) not in \
            ("succeeded", "failed", "cancelled") and time.monotonic() < deadline:
        time.sleep(0.2)
    assert status == "succeeded"
    assert httpx.get(f"{second}/v1/level-jobs/{job}", timeout=10).json()["status"] == "succeeded"
    assert [level["name"] for level in httpx.get(f"{second}/v1/levels", timeout=10).json()["levels"]] == ["corridor"]
    again = httpx.post(f"{second}/v1/levels", data={"name": "corridor"},
                       files={"level": ("level.obj", obj_text(corridor()))}, timeout=30)
    assert again.status_code == 409  # the name is taken on every node
    raw = wc.GrpcRaw(cluster.nodes[1].grpc)
    try:
        times, feet = corridor_walk(2.0)
        session_id = raw.call("CreateSession", tracks_request("corridor", feet[0])).session_id
        check_directed(raw.stream(actor_frames(session_id, times, feet)), feet)
    finally:
        raw.close()


def test_live_streams_go_on_while_a_node_joins(cluster, stub):
    keys = new_keys(4)
    sessions = [create(stub, key) for key in keys]
    joined, results = threading.Event(), {}

    def stream(key: str, session_id: str) -> None:
        sent = []

        def paced():  # 50 Hz until half a second after the join
            for update in wc.walk(session_id, 100_000):
                if joined.is_set() and time.monotonic() > joined.at + 0.5:
                    return
                sent.append(update.frame)
                yield update
                time.sleep(0.02)
        try:
            replies = [r.frame for r in stub.StreamFrames(paced(), metadata=route(key), timeout=60)]
            results[key] = (sent, replies)
        except grpc.RpcError as exc:
            results[key] = exc

    threads = [threading.Thread(target=stream, args=pair) for pair in zip(keys, sessions)]
    for t in threads:
        t.start()
    time.sleep(0.5)
    node = cluster.add_node()
    joined.at = time.monotonic()
    joined.set()
    for t in threads:
        t.join(30)
    for key in keys:
        assert not isinstance(results[key], Exception), results[key]
        sent, replies = results[key]
        assert len(sent) > 50 and replies == sent
    assert node.node_id == "node-3"
    new = new_keys(12)
    placed = [create(stub, key) for key in new]
    held = sessions_by_node(cluster)
    assert [node_of(held, sid) for sid in placed] == predicted(cluster, new)


def test_a_killed_node_is_marked_down_and_its_keys_go_to_the_others(cluster, stub):
    victim = cluster.nodes[0].node_id
    keys = [k for k, n in zip(*(lambda ks: (ks, predicted(cluster, ks)))(new_keys(40))) if n == victim][:4]
    old_sessions = [create(stub, key) for key in keys]
    cluster.kill_node(0)
    killed_at = time.monotonic()
    # before any check has failed, a refused connection is retried on another node (redispatch)
    create(stub, keys[0])
    cluster.haproxy.wait_until({victim: "DOWN"}, timeout_s=10, backends=(GRPC_BACKEND,))
    assert time.monotonic() - killed_at < 5.0
    moved = [create(stub, key) for key in keys]
    held = sessions_by_node(cluster)
    assert [node_of(held, sid) for sid in moved] == predicted(cluster, keys, without=(victim,))
    for key, session_id in zip(keys, old_sessions):
        # the node that takes the key restores the session from its checkpoint in Redis
        answer = stub.Frame(next(wc.walk(session_id, 1)), metadata=route(key), timeout=30)
        assert answer.frame == 1 and not answer.stale
    held = sessions_by_node(cluster)
    assert [node_of(held, sid) for sid in old_sessions] == predicted(cluster, keys, without=(victim,))

    for index in range(1, len(cluster.nodes)):
        cluster.kill_node(index)
    cluster.haproxy.wait_until({n.node_id: "DOWN" for n in cluster.nodes}, timeout_s=10, backends=(GRPC_BACKEND,))
    with pytest.raises(grpc.RpcError) as failed:
        create(stub, keys[0])
    assert failed.value.code() == grpc.StatusCode.UNAVAILABLE  # HAProxy's 503, as gRPC maps it
