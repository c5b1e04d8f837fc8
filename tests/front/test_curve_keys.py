"""The ZeroMQ server's CURVE key pair: made once, the secret half readable by its owner only, and
one pair for nodes that start together on one data directory."""

from __future__ import annotations

import os
import stat
import threading

from camdirector.front.zmq_service import CURVE_DIR, curve_server_keys


def test_nodes_starting_together_on_one_folder_agree_on_one_pair(tmp_path):
    pairs = []
    threads = [threading.Thread(target=lambda: pairs.append(curve_server_keys(tmp_path))) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(set(pairs)) == 1 and len(pairs) == 8
    folder = tmp_path / CURVE_DIR
    assert sorted(os.listdir(folder)) == ["server.key", "server.key_secret"]  # nothing left aside
    assert stat.S_IMODE(os.stat(folder / "server.key_secret").st_mode) == 0o600
    assert pairs[0][0].decode() in (folder / "server.key").read_text()  # clients read the public half there
    assert curve_server_keys(tmp_path) == pairs[0]  # and a restart keeps it
