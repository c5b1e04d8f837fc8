"""The protocol the C/C++ SDK speaks: CD_PROTOCOL and cd_protocol() (from C, tools/c_api_check.c)
are the server's; against a real server (`sdk_check protocol`) cd_session_open says it in
CreateSessionRequest.client_protocol (read back from the server's recording of the session, with
the targets' display names: cd_target.display_name, NULL as empty), a
request claiming a newer one is CD_FAILED_PRECONDITION with the server's words in cd_last_error,
and the same client then opens another session."""

from __future__ import annotations

from camdirector.deploy.server_process import ServerProcess
from camdirector.version import PROTOCOL, VERSION
from camdirector.worker.recording import read_entries
from tests.client_sdk.cpp.conftest import run_json


def test_the_c_interface_says_the_servers_protocol(sdk_bin):
    report = run_json(sdk_bin / "c_api_check")
    assert report["protocol"] == report["header_protocol"] == PROTOCOL, report


def test_sessions_say_the_protocol_and_a_newer_claim_is_refused(sdk_bin, tmp_path):
    with ServerProcess("--workers", "1", "--data-dir", str(tmp_path), transports=("grpc",)) as server:
        report = run_json(sdk_bin / "sdk_check", "protocol", server.grpc)
        log = server.log_tail()  # an edge that ended the client's connection says why there
    assert report["protocol"] == report["header_protocol"] == PROTOCOL, report
    assert report["recorded_close"] == "OK", (report["recorded_close_error"], log)  # the whole report's repr is cut short
    recording = tmp_path / "recordings" / f"{report['recorded_session_id']}.cdrec"
    create = next(read_entries(recording)).create
    assert create.client_protocol == PROTOCOL
    assert [t.display_name for t in create.targets] == ["Åsa <b>", ""]  # cd_target.display_name, NULL for b
    assert report["newer"] == "FAILED_PRECONDITION", report
    assert report["newer_error"] == (
        f"CreateSession on {server.grpc}: this client speaks camdirector protocol {PROTOCOL + 1}, this server "
        f"(camdirector {VERSION}) protocol {PROTOCOL}: upgrade the server, or use a client of release {VERSION}"
    ), report
    assert report["reopened"] and report["close"] == "OK", (report, log)
