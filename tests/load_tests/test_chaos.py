"""load_tests.chaos at its --short size, in `make test`: two nodes behind HAProxy, two sessions
through each fault, 4 s faults. Asserted is only what holds whatever the machine's speed: the run
completes, every node is back up at the end, no stream still hangs, no frame is answered twice to
the application, and a SIGSTOPped node leaves the balancer (its checks time out within 1.2 s:
deploy/haproxy.py), and what issue 40 fixed: a PostgreSQL pause neither freezes the streams nor
takes a node out, a balancer down for 6 s costs the application nothing, a node lost during
a Redis outage rewinds no session, and the overview jobs submitted through every fault are
neither lost nor run twice. The other figures are printed, never asserted."""

from __future__ import annotations

import json

import pytest

from load_tests.chaos import FAULTS, SHORT, run
from tests.conftest import SHARED_DATA, service_or_skip

CLIP = "mocap/bandai_namco/dataset-1_run_active_001.bvh"  # the overview jobs' clip, 72 frames


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> dict:
    """The short run; with the overview jobs where the shared data is (the streams' figures need
    none of it: in a clone without it, only the jobs' tests skip)."""
    clip = SHARED_DATA / CLIP if SHARED_DATA.is_dir() else None
    result = service_or_skip(
        lambda: run(FAULTS, nodes=2, sessions=2, timing=SHORT, folder=tmp_path_factory.mktemp("chaos"), clip=clip)
    )
    print(json.dumps(result, indent=1))
    return result


def test_the_run_completes_and_every_node_is_back_up(report):
    assert list(report["faults"]) == list(FAULTS)
    assert report["every_node_up_at_end"]
    for name, fault in report["faults"].items():
        assert fault["sessions"] == 2, (name, fault["create_errors"])
        assert fault["streams_hung_at_end"] == 0, name
        assert fault["frames_answered"] > 0, name


def test_no_frame_is_answered_twice_to_the_application(report):
    assert {name: f["frames_answered_twice"] for name, f in report["faults"].items()} == dict.fromkeys(FAULTS, 0)


def test_a_paused_node_leaves_the_balancer_and_its_streams_go_on_elsewhere(report):
    """A stream left on the paused node cannot be answered until it resumes: its stall is at
    least the pause, however fast the machine. Cut when the node is marked down, it is opened
    again on a live node after the checks' 1.2 s at worst and the SDK's reopening."""
    fault = report["faults"]["node-pause"]
    assert fault["node"] in fault["balancer"]["nodes_out_s"], fault["balancer"]
    assert fault["stall_s_max"] < SHORT.fault_s
    # out of the balancer, and every session of the node answered elsewhere, while it still hangs
    assert fault["out_after_hang_s"] is not None and fault["out_after_hang_s"] < SHORT.fault_s, fault
    assert fault["resumed_after_hang_s_max"] is not None and fault["resumed_after_hang_s_max"] < SHORT.fault_s, fault


def test_a_postgresql_pause_does_not_freeze_the_streams(report):
    assert report["faults"]["pg-pause"]["stall_s_max"] < SHORT.fault_s / 2


def test_a_postgresql_pause_takes_no_node_out_of_the_balancer(report):
    assert report["faults"]["pg-pause"]["balancer"]["nodes_out_s"] == {}


def test_a_balancer_down_for_6_s_raises_nothing_and_loses_no_frame(report):
    fault = report["faults"]["haproxy-6s"]
    assert fault["errors_raised"] == {} and fault["frames_lost"] == 0


def test_a_node_lost_during_a_redis_outage_rewinds_no_session(report):
    assert report["faults"]["node-kill-redis-down"]["frames_pose_differs"] == 0


def jobs_of(report) -> dict:
    return {name: f["jobs"] for name, f in report["faults"].items()}


# The jobs' tests take `shared_data`: skipped without it (a failure under CI), as the run then had no clip.
def test_every_job_submitted_through_a_fault_is_accounted_for(report, shared_data):
    for name, jobs in jobs_of(report).items():
        assert jobs["jobs_accepted"] > 0, (name, jobs)
        assert jobs["jobs_succeeded"] + jobs["jobs_failed"] + jobs["jobs_lost"] == jobs["jobs_accepted"], (name, jobs)


def test_no_job_is_lost_failed_or_run_twice_through_any_fault(report, shared_data):
    jobs = jobs_of(report)
    assert {
        n: (j["jobs_lost"], j["jobs_failed"], j["jobs_run_again"], j["jobs_made_twice"]) for n, j in jobs.items()
    } == dict.fromkeys(FAULTS, (0, 0, 0, 0)), jobs
