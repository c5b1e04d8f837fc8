"""A client written only from the .proto files (no SDK), over gRPC or ZeroMQ, and scene builders."""

from __future__ import annotations

import grpc
import numpy as np
import zmq

from camdirector.v1 import director_pb2 as pb
from camdirector.v1 import director_pb2_grpc as pbg

REPLY_TYPES = {
    "CreateSession": pb.CreateSessionResponse,
    "Frame": pb.CameraUpdate,
    "UpdateStyle": pb.UpdateStyleResponse,
    "CloseSession": pb.CloseSessionResponse,
    "TakeShot": pb.TakeShotResponse,
}


class RpcFailed(Exception):
    def __init__(self, code: grpc.StatusCode, message: str):
        super().__init__(f"{code.name}: {message}")
        self.code, self.message = code, message


class GrpcRaw:
    """`key`: sent as `authorization: Bearer KEY` metadata; `ca_file`: TLS trusting that CA."""

    def __init__(self, address: str, key: str | None = None, ca_file=None):
        options = [("grpc.max_send_message_length", 256 << 20)]
        if ca_file is not None:
            credentials = grpc.ssl_channel_credentials(open(ca_file, "rb").read())
            self.channel = grpc.secure_channel(address, credentials, options=options)
        else:
            self.channel = grpc.insecure_channel(address, options=options)
        self.stub = pbg.DirectorStub(self.channel)
        self.metadata = [("authorization", f"Bearer {key}")] if key else None

    def call(self, rpc: str, request):
        try:
            return getattr(self.stub, rpc)(request, timeout=30, metadata=self.metadata)
        except grpc.RpcError as exc:
            raise RpcFailed(exc.code(), exc.details()) from None

    def stream(self, frames):
        try:
            return list(self.stub.StreamFrames(iter(frames), timeout=60, metadata=self.metadata))
        except grpc.RpcError as exc:
            raise RpcFailed(exc.code(), exc.details()) from None

    def close(self):
        self.channel.close()


class ZmqRaw:
    """`key`: sent as the request's third frame; `server_key`: the server's CURVE public key."""

    def __init__(self, address: str, key: str | None = None, server_key: str | None = None):
        self.ctx = zmq.Context.instance()
        self.sock = self.ctx.socket(zmq.DEALER)
        self.sock.setsockopt(zmq.LINGER, 0)
        self.sock.setsockopt(zmq.RCVTIMEO, 30000)
        if server_key is not None:
            self.sock.curve_serverkey = server_key.encode()
            self.sock.curve_publickey, self.sock.curve_secretkey = zmq.curve_keypair()
        self.key_frame = [f"Bearer {key}".encode()] if key else []
        self.sock.connect(address)

    def send_raw(self, frames: list[bytes]) -> list[bytes]:
        self.sock.send_multipart(frames)
        return self.sock.recv_multipart()

    def call(self, rpc: str, request):
        code, body = self.send_raw([rpc.encode(), request.SerializeToString(), *self.key_frame])
        if code != b"0":
            raise RpcFailed(grpc.StatusCode[_name(int(code))], body.decode())
        return REPLY_TYPES[rpc].FromString(body)

    def stream(self, frames):
        return [self.call("Frame", f) for f in frames]

    def close(self):
        self.sock.close()


def _name(value: int) -> str:
    return next(c.name for c in grpc.StatusCode if c.value[0] == value)


def capsule_target(target_id="hero", position=(0.0, 0.9, 0.0), aim=(0.0, 0.6, 0.0)) -> pb.Target:
    return pb.Target(
        id=target_id,
        mesh=pb.Mesh(primitive=pb.Primitive(capsule=pb.Primitive.Capsule(radius=0.3, height=1.8))),
        transform=pb.Transform(position=pb.Vec3(x=position[0], y=position[1], z=position[2])),
        aim_offset=pb.Vec3(x=aim[0], y=aim[1], z=aim[2]),
    )


def box_object(object_id, position, size=(1.0, 3.0, 1.0), dynamic=False) -> pb.SceneObject:
    return pb.SceneObject(
        id=object_id,
        dynamic=dynamic,
        mesh=pb.Mesh(primitive=pb.Primitive(box=pb.Primitive.Box(size=pb.Vec3(x=size[0], y=size[1], z=size[2])))),
        transform=pb.Transform(position=pb.Vec3(x=position[0], y=position[1], z=position[2])),
    )


def two_target_request(**kwargs) -> pb.CreateSessionRequest:
    return pb.CreateSessionRequest(
        targets=[capsule_target("a", (0.0, 0.9, 0.0)), capsule_target("b", (3.0, 0.9, 1.0))],
        objects=[box_object("pillar", (1.5, 1.5, 4.0)), box_object("cart", (-2.0, 0.5, 2.0), (1, 1, 1), True)],
        **kwargs,
    )


def walk(session_id: str, n: int, start_frame: int = 1, target_id: str = "a"):
    """FrameUpdates of target `target_id` walking a curve at 60 Hz, the cart sliding along x."""
    for i in range(start_frame, start_frame + n):
        t = i / 60.0
        yield pb.FrameUpdate(
            session_id=session_id,
            frame=i,
            time_s=t,
            states=[
                pb.ObjectState(
                    id=target_id,
                    transform=pb.Transform(
                        position=pb.Vec3(x=np.sin(0.5 * t) * 2.0, y=0.9, z=1.4 * t),
                        rotation=pb.Quat(y=np.sin(0.25 * t), w=np.cos(0.25 * t)),
                    ),
                ),
                pb.ObjectState(id="cart", transform=pb.Transform(position=pb.Vec3(x=-2.0 + np.sin(t), y=0.5, z=2.0))),
            ],
        )
