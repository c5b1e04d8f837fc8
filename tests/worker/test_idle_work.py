"""A worker's idle moments (SessionTable.idle_work) move deferred work earlier, never change an answer."""

from __future__ import annotations

from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.dispatch import Dispatcher
from camdirector.worker.replay import _comparable
from camdirector.worker.table import SessionTable
from tests.service.wire_client import two_target_request, walk


def _run(tmp_path, idle: bool) -> tuple[list, int]:
    """The comparable answers of an ANTICIPATION session over 90 frames and a style change, and how
    many deferred map updates idle_work did (with `idle`, after every request, as a worker does)."""
    table = SessionTable(ServerSettings(data_dir=str(tmp_path), checkpoint_store="off"))
    requests = Dispatcher(table)
    requests.handle_bytes(
        "create", "s", two_target_request(style=pb.Style(visibility=pb.ANTICIPATION), seed=3).SerializeToString()
    )
    inputs = [("frame", f.SerializeToString()) for f in walk("s", 90)]
    style = pb.UpdateStyleRequest(session_id="s", style=pb.Style(visibility=pb.ANTICIPATION, mask=pb.STYLE_MASK_SOFT_BEHIND))
    inputs.insert(45, ("style", style.SerializeToString()))
    answers, done = [], 0
    for op, payload in inputs:
        body, _ = requests.handle_bytes(op, "s", payload)
        if op == "frame":
            answers.append(_comparable(pb.CameraUpdate.FromString(body)))
        while idle and table.held["s"].session.has_deferred_work:
            table.idle_work()
            done += 1
    table.close_all()
    return answers, done


def test_deferred_map_updates_done_when_idle_give_the_same_answers(tmp_path):
    lazy, none_done = _run(tmp_path / "lazy", idle=False)
    eager, done = _run(tmp_path / "eager", idle=True)
    assert none_done == 0 and done >= 10  # 1.5 s at one amortized update every 0.1 s
    assert eager == lazy
