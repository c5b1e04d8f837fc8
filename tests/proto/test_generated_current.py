"""The committed generated code matches proto/camdirector/v1/director.proto (run `make proto`)."""

from __future__ import annotations

import shutil
from pathlib import Path

from grpc_tools import protoc

PROTO_ROOT = Path(__file__).resolve().parents[2] / "proto"
GENERATED = ["director_pb2.py", "director_pb2.pyi", "director_pb2_grpc.py"]


def test_generated_code_is_current(tmp_path):
    shutil.copytree(
        PROTO_ROOT / "camdirector", tmp_path / "camdirector", ignore=shutil.ignore_patterns("*.py", "*.pyi", "__pycache__")
    )
    code = protoc.main(
        [
            "protoc",
            f"-I{tmp_path}",
            f"--python_out={tmp_path}",
            f"--pyi_out={tmp_path}",
            f"--grpc_python_out={tmp_path}",
            str(tmp_path / "camdirector/v1/director.proto"),
        ]
    )
    assert code == 0
    for name in GENERATED:
        fresh = (tmp_path / "camdirector/v1" / name).read_text()
        committed = (PROTO_ROOT / "camdirector/v1" / name).read_text()
        assert fresh == committed, f"{name} is stale: run `make proto`"


def test_contract_names_clients_rely_on():
    from camdirector.v1 import director_pb2 as pb

    service = pb.DESCRIPTOR.services_by_name["Director"]
    assert {m.name for m in service.methods} >= {"CreateSession", "StreamFrames", "UpdateStyle", "CloseSession"}
    stream = service.methods_by_name["StreamFrames"]
    assert stream.client_streaming and stream.server_streaming
    fields = {
        name: [f.name for f in pb.DESCRIPTOR.message_types_by_name[name].fields]
        for name in ("Vec3", "Quat", "Transform", "CreateSessionRequest", "FrameUpdate", "CameraUpdate", "CameraPose")
    }
    assert fields["Vec3"][:3] == ["x", "y", "z"] and fields["Quat"][:4] == ["x", "y", "z", "w"]
    assert fields["Transform"][:3] == ["position", "rotation", "scale"]
    assert fields["CreateSessionRequest"][:5] == ["objects", "targets", "lens", "style", "seed"]
    assert fields["FrameUpdate"][:4] == ["session_id", "frame", "time_s", "states"]
    assert fields["CameraUpdate"][:7] == ["frame", "time_s", "pose", "cut", "shot_id", "visibility", "compute_ms"]
    assert [v.name for v in pb.VisibilityMode.DESCRIPTOR.values] == [
        "VISIBILITY_MODE_UNSPECIFIED",
        "ANTICIPATION",
        "NO_ANTICIPATION",
        "RAYCAST",
        "REACTIVE",
        "FRAMING_ONLY",
    ]
    assert [f.name for f in pb.Mesh.DESCRIPTOR.oneofs_by_name["source"].fields][:3] == ["glb", "obj", "triangles"]
