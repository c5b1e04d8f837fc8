"""The cluster on one machine, through HAProxy (deploy/cluster.py, deploy/haproxy.py), as it is
deployed: TLS on every hop and a key on every call. One route key keeps every call of a session on
one node, route keys spread over the nodes where HAProxy's ring puts them (load_tests/ring_sim.py's
model), a node that joins breaks no live stream, a node that dies is marked down within seconds,
its route keys going to the others; with no node left, UNAVAILABLE. An API key revoked through one
node is refused by the others: at once for every call but a frame, and a stream on another node
is ended within a second. The tests run in order on one cluster: the join adds node-3, the last
test kills nodes and the very last starts one again."""

from __future__ import annotations

import threading
import time

import grpc
import httpx
import pytest

from camdirector.deploy.haproxy import GRPC_BACKEND, ROUTE_HEADER
from camdirector.v1 import director_pb2_grpc as pbg
from load_tests.ring_sim import Ring, key_hashes
from tests.deploy.conftest import channel, https, make_key, new_keys, node_of, route, sessions_by_node, trusting
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
    (node,) = [n for n in cluster.nodes if n.node_id == node_id]
    status, listing = https(cluster, node.http, "/v1/sessions", cluster.admin_key)
    assert status == 200, listing
    return listing["sessions"]


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
        status, session = https(
            cluster, cluster.http, f"/v1/sessions/{session_id}", cluster.admin_key, headers={ROUTE_HEADER: key}
        )
        assert status == 200, session


def test_a_level_added_through_one_node_directs_a_session_on_the_other(cluster):
    """Job and level records in PostgreSQL, artifacts in the shared folder: the level job of one
    node's REST API is seen by the other, which lists the level and directs a TRACKS session on it."""
    from tests.precompute.tracks.tiny_levels import corridor
    from tests.service.tracks_sessions import actor_frames, check_directed, corridor_walk, obj_text, tracks_request

    def admin(node) -> httpx.Client:
        return httpx.Client(
            base_url=f"https://{node.http}",
            verify=trusting(cluster),
            timeout=30,
            headers={"Authorization": f"Bearer {cluster.admin_key}"},
        )

    with admin(cluster.nodes[0]) as first, admin(cluster.nodes[1]) as second:
        upload = {"level": ("level.obj", obj_text(corridor()))}
        posted = first.post("/v1/levels", data={"name": "corridor"}, files=upload)
        assert posted.status_code == 202, posted.text
        job = posted.json()["id"]
        deadline = time.monotonic() + 120
        while (status := first.get(f"/v1/level-jobs/{job}").json()["status"]) not in (
            "succeeded",
            "failed",
            "cancelled",
        ) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert status == "succeeded"
        assert second.get(f"/v1/level-jobs/{job}").json()["status"] == "succeeded"
        assert [level["name"] for level in second.get("/v1/levels").json()["levels"]] == ["corridor"]
        again = second.post("/v1/levels", data={"name": "corridor"}, files=upload)
        assert again.status_code == 409  # the name is taken on every node
    raw = wc.GrpcRaw(cluster.nodes[1].grpc, key=cluster.admin_key, ca_file=cluster.ca_file)
    try:
        times, feet = corridor_walk(2.0)
        session_id = raw.call("CreateSession", tracks_request("corridor", feet[0])).session_id
        check_directed(raw.stream(actor_frames(session_id, times, feet)), feet)
    finally:
        raw.close()


def _stream_until_ended(stub, session_id: str, metadata, ended: dict) -> None:
    """Streams frames into the session at 60 Hz (10 s at most); notes in `ended` how many were
    answered and when and how the stream was ended."""

    def paced():
        for update in wc.walk(session_id, 600):
            yield update
            time.sleep(1 / 60)

    ended["answered"] = 0
    try:
        for _ in stub.StreamFrames(paced(), metadata=metadata, timeout=30):
            ended["answered"] += 1
    except grpc.RpcError as exc:
        ended.update(at=time.monotonic(), code=exc.code(), details=exc.details())


def test_a_key_revoked_through_one_node_is_refused_by_the_others(cluster):
    """The nodes share their keys through PostgreSQL. Two engine keys are made through node-1, and
    revoked there with DELETE /v1/keys/{id}. The first is refused by node-2 at once for every call
    but a frame: 401 to REST calls (401, not the 403 its role earned before: the key itself is
    refused), UNAUTHENTICATED to a CreateSession the balancer sends to node-2. The second streams
    into two sessions on node-2, one through the balancer and one at node-2's own address; both
    streams end within a second of its revocation (node-2 looks for revoked keys every 0.25 s:
    access/guard.py; nothing else asks node-2 about it meanwhile; the times are printed):
    UNAUTHENTICATED at node-2's address; through the balancer often CANCELLED instead, as HAProxy 2.6
    resets the client's side of a stream that a node ends while the client is still sending,
    losing the status (haproxy/haproxy#1219; docs/scaling.md), so the next call shows the refusal."""
    first, second = cluster.nodes[:2]
    checked, streaming = make_key(cluster, "engine", first.http), make_key(cluster, "engine", first.http)
    keys = new_keys(40)
    balanced_route, direct_route, create_route = [k for k, n in zip(keys, predicted(cluster, keys)) if n == second.node_id][:3]
    with (
        channel(cluster, cluster.grpc, checked["key"]) as checked_channel,
        channel(cluster, cluster.grpc, streaming["key"]) as balanced,
        channel(cluster, second.grpc, streaming["key"]) as direct,
    ):
        checked_stub = pbg.DirectorStub(checked_channel)
        stubs = {"balancer": pbg.DirectorStub(balanced), second.node_id: pbg.DirectorStub(direct)}
        sessions = {
            "balancer": create(stubs["balancer"], balanced_route),
            second.node_id: create(stubs[second.node_id], direct_route),
        }
        held = sessions_by_node(cluster)
        assert {node_of(held, session_id) for session_id in sessions.values()} == {second.node_id}
        assert https(cluster, second.http, "/v1/whoami", checked["key"])[0] == 200
        assert https(cluster, second.http, "/v1/sessions", checked["key"])[0] == 403  # an engine lists nothing
        create(checked_stub, create_route)

        status, record = https(cluster, first.http, f"/v1/keys/{checked['id']}", cluster.admin_key, "DELETE")
        assert status == 200 and record["revoked_s"] is not None, record
        assert https(cluster, second.http, "/v1/whoami", checked["key"])[0] == 401
        assert https(cluster, second.http, "/v1/sessions", checked["key"])[0] == 401
        with pytest.raises(grpc.RpcError) as refused:
            create(checked_stub, create_route)
        assert refused.value.code() == grpc.StatusCode.UNAUTHENTICATED, refused.value

        ended = {via: {} for via in stubs}
        threads = [
            threading.Thread(target=_stream_until_ended, args=(stubs[via], sessions[via], route(r), ended[via]))
            for via, r in (("balancer", balanced_route), (second.node_id, direct_route))
        ]
        for thread in threads:
            thread.start()
        time.sleep(1.0)
        asked = time.monotonic()
        status, record = https(cluster, first.http, f"/v1/keys/{streaming['id']}", cluster.admin_key, "DELETE")
        answered = time.monotonic()
        assert status == 200 and record["revoked_s"] is not None, record
        for thread in threads:
            thread.join(15)
        with pytest.raises(grpc.RpcError) as refused:
            stubs["balancer"].Frame(next(wc.walk(sessions["balancer"], 1)), metadata=route(balanced_route), timeout=30)
        assert refused.value.code() == grpc.StatusCode.UNAUTHENTICATED, refused.value
    for via, stream in ended.items():
        assert "code" in stream, (via, stream)  # ended, not run out
        print(
            f"stream via {via}: {stream['answered']} frames answered, ended {stream['code'].name} "
            f"{stream['at'] - answered:.3f} s after the revocation through {first.node_id} answered "
            f"({stream['at'] - asked:.3f} s after it was asked)"
        )
        assert stream["answered"] > 30  # it streamed for a second before
        assert stream["at"] - asked < 1.0
    assert ended[second.node_id]["code"] == grpc.StatusCode.UNAUTHENTICATED
    assert "revoked" in ended[second.node_id]["details"]
    assert ended["balancer"]["code"] in (grpc.StatusCode.UNAUTHENTICATED, grpc.StatusCode.CANCELLED)


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


def test_a_killed_node_started_again_is_back_on_its_ports(cluster, stub):
    """After the test above every node is dead. `restart_node` (the chaos benchmark's) starts one
    where HAProxy knows it; it is marked UP and takes every call (the only node up)."""
    before = cluster.nodes[0]
    after = cluster.restart_node(0)
    assert (after.grpc, after.http, after.zmq) == (before.grpc, before.http, before.zmq) and after.pid != before.pid
    create(stub, new_keys(1)[0])
