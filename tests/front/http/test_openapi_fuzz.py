"""Every REST route fuzzed from the server's own OpenAPI document (schemathesis) against a real
`camdirector serve`: no answer is a 5xx, and every answer's status, content type, headers and body
are ones the document declares, for valid and invalid requests alike, wrong methods included.
The server runs with authentication on and the fuzzer sends its admin key; schemathesis' own
authentication checks send requests without it and with a wrong one, which must answer 401. The
document is an admin's (`GET /openapi.json` with the key): the test reads it so and hands the
fuzzer the file.

Left out: schemathesis' `positive_data_acceptance`, which sends the string "null" for optional
multipart fields (multipart has no null) and integers just past a 2**63 - 1 bound after float
rounding, and calls their 422 a bug.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import httpx

from camdirector.deploy.server_process import ServerProcess

SEED = 20261123
EXAMPLES = 25


def test_rest_api_conforms_to_its_openapi_document(tmp_path):
    server = ServerProcess(
        "--workers",
        "0",
        "--data-dir",
        str(tmp_path / "data"),
        "--max-upload-bytes",
        str(64 * 1024),
        transports=("http",),
        auth=True,
    )
    try:
        document = httpx.get(f"http://{server.http}/openapi.json", headers={"Authorization": f"Bearer {server.admin_key}"})
        assert document.status_code == 200, document.text
        (tmp_path / "openapi.json").write_bytes(document.content)
        run = subprocess.run(
            [
                str(Path(sys.executable).with_name("schemathesis")),
                "run",
                str(tmp_path / "openapi.json"),
                "--url",
                f"http://{server.http}",
                "--checks",
                "all",
                "--exclude-checks",
                "positive_data_acceptance",
                "--phases",
                "examples,coverage,fuzzing",
                "--max-examples",
                str(EXAMPLES),
                "--seed",
                str(SEED),
                "--generation-database",
                "none",
                "--request-timeout",
                "30",
                "--no-color",
                "--header",
                f"Authorization: Bearer {server.admin_key}",
            ],
            capture_output=True,
            text=True,
            timeout=600,
            cwd=tmp_path,
        )
        assert server.alive(), server.log_tail()
    finally:
        server.stop()
    assert run.returncode == 0, run.stdout[-6000:] + run.stderr[-2000:]
