"""Makes a session recording (`.cdrec`, worker/recording.py) again from its inputs, on a frame path.

    .venv/bin/python scripts/remake_recording.py SOURCE OUT [--frame-path compiled|python] [--states]
    .venv/bin/python scripts/remake_recording.py --tumbling OUT [--visibility MODE] [--frame-path ...] [--states]

The first form reads SOURCE's inputs (its creation request, then its frames, style changes and
takes in the order they came) and runs them through a fresh session table of this checkout that
records, as a server with `record = true` would: OUT is what today's code on that frame path
answers to the same inputs (the recorded frames' bytes are passed through unchanged). SOURCE
may be OUT. The second form makes the `tumbling` inputs (`tumbling_inputs`) and records them.
With --states, frames that carry `packed_transforms` carry the same numbers as `states` instead
(`as_states`): the codec decodes those otherwise (tests/data/recordings/README.md says why it matters).

This is how tests/data/recordings/compiled/ was made (its README.md): a change that means to
change what a camera does makes them again with this script and says so.
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
import tempfile
from collections.abc import Iterable
from pathlib import Path

import camdirector_client as cd
from camdirector.server_settings import FRAME_PATHS, ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.codec import PACKED_STRIDE
from camdirector.worker.recording import read_entries
from camdirector.worker.table import SessionTable

Input = pb.FrameUpdate | pb.UpdateStyleRequest | pb.TakeShotRequest


def inputs_of(path: Path) -> tuple[pb.CreateSessionRequest, list[Input]]:
    """A recording's creation request and inputs, in order (its answers left out)."""
    entries = list(read_entries(path))
    if not entries or entries[0].WhichOneof("entry") != "create":
        raise ValueError(f"{path} does not start with a creation request")
    inputs: list[Input] = []
    for entry in entries[1:]:
        kind = entry.WhichOneof("entry")
        if kind == "frame":
            inputs.append(entry.frame)
        elif kind == "style":
            inputs.append(entry.style)
        elif kind == "take":
            inputs.append(entry.take)
    return entries[0].create, inputs


def as_states(inputs: Iterable[Input]) -> list[Input]:
    """The inputs with each frame's `packed_transforms` sent as `states` (ObjectState per packed id,
    its position, rotation and scale the packed numbers)."""
    out: list[Input] = []
    for msg in inputs:
        if isinstance(msg, pb.FrameUpdate) and msg.packed_ids:
            values = list(msg.packed_transforms)
            frame = pb.FrameUpdate()
            frame.CopyFrom(msg)
            frame.ClearField("packed_ids")
            frame.ClearField("packed_transforms")
            for i, object_id in enumerate(msg.packed_ids):
                x, y, z, qx, qy, qz, qw, sx, sy, sz = values[PACKED_STRIDE * i : PACKED_STRIDE * (i + 1)]
                transform = pb.Transform(
                    position=pb.Vec3(x=x, y=y, z=z), rotation=pb.Quat(x=qx, y=qy, z=qz, w=qw), scale=pb.Vec3(x=sx, y=sy, z=sz)
                )
                frame.states.add(id=object_id, transform=transform)
            msg = frame
        out.append(msg)
    return out


def record(create: pb.CreateSessionRequest, inputs: Iterable[Input], out: Path, frame_path: str) -> None:
    """Runs the inputs through a recording session table on `frame_path` and writes its recording to `out`."""
    with tempfile.TemporaryDirectory() as data_dir:
        settings = ServerSettings(data_dir=data_dir, checkpoint_store="off", frame_path=frame_path)
        table = SessionTable(settings)
        request = pb.CreateSessionRequest()
        request.CopyFrom(create)
        request.record = True
        session_id = "s"
        table.create(session_id, request)
        for msg in inputs:
            msg.session_id = session_id
            if isinstance(msg, pb.FrameUpdate):
                table.frame_bytes(msg, msg.SerializeToString())
            elif isinstance(msg, pb.UpdateStyleRequest):
                table.update_style(msg)
            else:
                table.take_shot(msg)
        table.close_all()
        out.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(settings.recordings_dir / f"{session_id}.cdrec", out)


def tumbling_inputs(frames: int = 240, visibility: int = pb.FRAMING_ONLY) -> tuple[pb.CreateSessionRequest, list[Input]]:
    """One capsule target tumbling about a tilted axis while it walks, its aim point off its axis;
    a tilted static box and a tilted static capsule; a cylinder that turns as it slides past;
    packed states; the composition changed half way. Every rotation is about a tilted axis, so
    every carried point (aim points, visibility samples, the static meshes in the world, the
    primitives stood up) has its last bits from a product of three terms, which numpy's matmul
    hands to OpenBLAS: the inputs on which the frame path's machine dependence shows. The creation
    request's three rotations are among those whose np.linalg.norm (OpenBLAS's dot) differs
    between its SkylakeX and Haswell or Sandybridge kernels. `visibility`: the style's mode
    throughout (a pb.VisibilityMode)."""

    def quat(axis: tuple[float, float, float], angle_rad: float) -> tuple[float, float, float, float]:
        norm = math.sqrt(sum(a * a for a in axis))
        s = math.sin(angle_rad / 2.0) / norm
        return axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle_rad / 2.0)

    def transform(position: tuple[float, float, float], rotation: tuple[float, float, float, float]) -> pb.Transform:
        x, y, z, w = rotation
        return pb.Transform(position=pb.Vec3(x=position[0], y=position[1], z=position[2]), rotation=pb.Quat(x=x, y=y, z=z, w=w))

    def primitive(**shape: object) -> pb.Mesh:
        return pb.Mesh(primitive=pb.Primitive(**shape))

    create = pb.CreateSessionRequest(
        targets=[
            pb.Target(
                id="hero",
                mesh=primitive(capsule=pb.Primitive.Capsule(radius=0.3, height=1.8)),
                transform=transform((0.0, 0.9, 0.0), quat((0.3, 1.0, 0.2), 0.39)),
                aim_offset=pb.Vec3(x=0.07, y=0.55, z=0.03),
            )
        ],
        objects=[
            pb.SceneObject(
                id="crate",
                mesh=primitive(box=pb.Primitive.Box(size=pb.Vec3(x=1.0, y=2.5, z=0.8))),
                transform=transform((1.4, 1.2, 3.0), quat((0.2, 1.0, -0.3), 0.52)),
            ),
            pb.SceneObject(
                id="post",
                mesh=primitive(capsule=pb.Primitive.Capsule(radius=0.25, height=2.4)),
                transform=transform((-1.1, 1.2, 2.4), quat((1.0, 0.1, 0.4), 0.35)),
            ),
            pb.SceneObject(
                id="drum",
                dynamic=True,
                mesh=primitive(cylinder=pb.Primitive.Cylinder(radius=0.4, height=1.2)),
                transform=transform((-3.0, 0.6, 1.5), quat((0.1, 1.0, 0.1), 0.0)),
            ),
        ],
        seed=11,
        style=pb.Style(visibility=visibility),
    )
    inputs: list[Input] = []
    for i in range(1, frames + 1):
        t = i / 60.0
        hero_at = (1.5 * math.sin(0.6 * t), 0.9 + 0.1 * math.sin(2.0 * t), 1.2 * t)
        drum_at = (-3.0 + 1.5 * t, 0.6, 1.5 + 0.3 * math.sin(t))
        ids, packed = cd.pack_states(
            ["hero", "drum"],
            [hero_at, drum_at],
            [quat((0.3, 1.0, 0.2), 0.4 + 0.9 * t), quat((0.1, 1.0, 0.1), 1.7 * t)],
        )
        inputs.append(pb.FrameUpdate(frame=i, time_s=t, packed_ids=ids, packed_transforms=packed))
        if i == frames // 2:
            inputs.append(pb.UpdateStyleRequest(style=pb.Style(visibility=visibility, screen_a=pb.ScreenPoint(x=-0.25, y=0.1))))
    return create, inputs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("source", type=Path, nargs="?", help="the recording whose inputs to record again")
    parser.add_argument("out", type=Path)
    parser.add_argument("--tumbling", action="store_true", help="record the tumbling inputs instead of a recording's")
    parser.add_argument("--frame-path", dest="frame_path", choices=FRAME_PATHS, default=ServerSettings.frame_path)
    parser.add_argument("--states", action="store_true", help="send packed transforms as states (as_states)")
    parser.add_argument(
        "--visibility", default="FRAMING_ONLY", choices=pb.VisibilityMode.keys()[1:], help="--tumbling: the style's mode"
    )
    args = parser.parse_args(argv)
    if args.tumbling == (args.source is not None):
        parser.error("give either SOURCE or --tumbling")
    if args.tumbling:
        create, inputs = tumbling_inputs(visibility=pb.VisibilityMode.Value(args.visibility))
    else:
        create, inputs = inputs_of(args.source)
    if args.states:
        inputs = as_states(inputs)
    record(create, inputs, args.out, args.frame_path)
    print(f"{args.out}: {sum(isinstance(i, pb.FrameUpdate) for i in inputs)} frames on the {args.frame_path} path")
    return 0


if __name__ == "__main__":
    sys.exit(main())
