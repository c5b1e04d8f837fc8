"""camdirector Python client: sessions over gRPC or ZeroMQ, and NumPy / game-engine conversions.

    import camdirector_client as cd

    with cd.connect("grpc://127.0.0.1:50051") as client:
        with client.create_session(targets=[cd.pb.Target(id="hero", ...)]) as session:
            update = session.frame(1, 1 / 60, packed=cd.pack_states(ids, positions, rotations))
            pose = cd.pose_from_msg(update.pose)

``pb`` is the wire contract's generated module (``camdirector.v1.director_pb2``); ``__version__``
this SDK's release, the same as the server's it was released with (a server says its own in
``/healthz`` and in every gRPC call's initial metadata, ``camdirector-version``).
"""

from importlib.metadata import version as _version

from camdirector.v1 import director_pb2 as pb
from camdirector_client.aio import AsyncClient, AsyncSession, connect_async
from camdirector_client.client import Client, Session, connect
from camdirector_client.convert import (
    Pose,
    camera_pose_to_unity,
    camera_pose_to_unreal,
    from_unity_position,
    from_unity_rotation,
    from_unity_scale,
    from_unreal_position,
    from_unreal_rotation,
    from_unreal_scale,
    horizontal_fov_deg,
    mesh_from_arrays,
    pack_states,
    pose_from_msg,
    quat,
    rotation_matrix,
    to_unity_position,
    to_unity_rotation,
    to_unity_scale,
    to_unreal_position,
    to_unreal_rotation,
    to_unreal_scale,
    transform_msg,
    unpack_states,
    vec3,
)
from camdirector_client.errors import DirectorError
from camdirector_client.wire import RetryPolicy

__version__ = _version("camdirector-client")

__all__ = [
    "AsyncClient",
    "AsyncSession",
    "Client",
    "DirectorError",
    "Pose",
    "RetryPolicy",
    "Session",
    "camera_pose_to_unity",
    "camera_pose_to_unreal",
    "connect",
    "connect_async",
    "from_unity_position",
    "from_unity_rotation",
    "from_unity_scale",
    "from_unreal_position",
    "from_unreal_rotation",
    "from_unreal_scale",
    "horizontal_fov_deg",
    "mesh_from_arrays",
    "pack_states",
    "pb",
    "pose_from_msg",
    "quat",
    "rotation_matrix",
    "to_unity_position",
    "to_unity_rotation",
    "to_unity_scale",
    "to_unreal_position",
    "to_unreal_rotation",
    "to_unreal_scale",
    "transform_msg",
    "unpack_states",
    "vec3",
]
