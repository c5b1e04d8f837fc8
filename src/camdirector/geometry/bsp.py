"""Quake BSP maps read into a level mesh: the world model's visible faces in metres, +Y up.

Formats (the header's first four bytes):
- BSP29 (int32 29): id Software's, id-Software/Quake WinQuake/bspfile.h and QW/client/bspfile.h
  (dheader_t, lump_t, dmodel_t, dface_t, dedge_t, texinfo_t, dmiptexlump_t, miptex_t);
- BSP2 ("BSP2") and the older RMQ variant ("2PSB"): the same lumps with 32-bit edges and faces,
  ericwa/ericw-tools include/common/bspfile_q1.hh (BSP2VERSION, BSP2RMQVERSION, bsp2_dface_t) and
  include/common/bspfile_generic.hh (bsp2_dedge_t). The two differ only in nodes and leafs, which
  this reader does not need.

What becomes triangles: model 0's faces (the world; doors, platforms and triggers are the other
models), each face's polygon read from its surfedges (a negative surfedge walks its edge
backwards) and fan-triangulated. Faces are left out by texture name, compared case-insensitively:
sky ("sky..."), liquids ("*..."; the engine marks both in QW/client/gl_model.c Mod_LoadFaces) and
any name holding "trigger" or "clip" (tool textures that are not walls). Quake winds a face
clockwise seen from its front (GLQuake culls with glCullFace(GL_FRONT), QW/client/gl_rmain.c;
each of dm2's 4914 world faces winds so about its plane's front normal), so each polygon is reversed: the triangles wind
counter-clockwise seen from the side a player sees, the convention the navmesh reads "up" from.

Units and axes: quake_frame.points_to_world (1/32 m per unit, Quake +Z up to world +Y up).

Every fault of the file (magic, a lump outside the file or of a size that is not a whole number
of records, an index out of range, a string without its end) raises MeshError naming the lump
and the byte offset in the file.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
import numpy.typing as npt

from camdirector.geometry.meshes import MeshError, TriMesh, from_arrays
from camdirector.geometry.quake_frame import points_to_world

LUMP_NAMES = (
    "entities",
    "planes",
    "textures",
    "vertexes",
    "visibility",
    "nodes",
    "texinfo",
    "faces",
    "lighting",
    "clipnodes",
    "leafs",
    "marksurfaces",
    "edges",
    "surfedges",
    "models",
)
_LUMP = {name: i for i, name in enumerate(LUMP_NAMES)}
HEADER_BYTES = 4 + 8 * len(LUMP_NAMES)
MODEL_BYTES = 64  # dmodel_t: mins, maxs, origin (9 floats), 4 headnodes, visleafs, firstface, numfaces
MODEL_FIRSTFACE_AT = 56
TEXINFO_BYTES = 40  # texinfo_t: vecs[2][4] floats, miptex, flags
TEXINFO_MIPTEX_AT = 32
MIPTEX_NAME_BYTES = 16
# Texture names (lower case) whose faces are not level geometry (module docstring).
_SKIPPED_PREFIXES = ("sky", "*")
_SKIPPED_WORDS = ("trigger", "clip")


@dataclass(frozen=True)
class _Format:
    name: str
    face: np.dtype[np.void]  # dface_t: planenum, side, firstedge, numedges, texinfo, styles[4], lightofs
    edge: np.dtype[np.void]  # dedge_t: two vertex numbers


_FACE29 = np.dtype(
    [
        ("planenum", "<i2"),
        ("side", "<i2"),
        ("firstedge", "<i4"),
        ("numedges", "<i2"),
        ("texinfo", "<i2"),
        ("styles", "u1", 4),
        ("lightofs", "<i4"),
    ]
)
_FACE2 = np.dtype(
    [
        ("planenum", "<i4"),
        ("side", "<i4"),
        ("firstedge", "<i4"),
        ("numedges", "<i4"),
        ("texinfo", "<i4"),
        ("styles", "u1", 4),
        ("lightofs", "<i4"),
    ]
)
_FORMATS = {
    struct.pack("<i", 29): _Format("BSP29", _FACE29, np.dtype(("<u2", 2))),
    b"BSP2": _Format("BSP2", _FACE2, np.dtype(("<u4", 2))),
    b"2PSB": _Format("2PSB", _FACE2, np.dtype(("<u4", 2))),
}


def _format(data: bytes) -> _Format:
    if len(data) < HEADER_BYTES:
        raise MeshError(
            f"BSP header: file of {len(data)} bytes is shorter than the {HEADER_BYTES}-byte header "
            f"(truncated at byte {len(data)})"
        )
    fmt = _FORMATS.get(bytes(data[:4]))
    if fmt is None:
        raise MeshError(f"BSP header at byte 0: version/magic {bytes(data[:4])!r} is not BSP29 (29), BSP2 or 2PSB")
    return fmt


def _lump(data: bytes, name: str, record_bytes: int = 1) -> tuple[int, memoryview]:
    """(file offset, bytes) of a lump, checked to lie in the file and hold whole records."""
    at = 4 + 8 * _LUMP[name]
    offset, length = struct.unpack_from("<ii", data, at)
    if offset < 0 or length < 0 or offset + length > len(data):
        raise MeshError(
            f"BSP {name} lump (header byte {at}): bytes {offset}..{offset + length} lie outside "
            f"the file of {len(data)} bytes (truncated or corrupt)"
        )
    if length % record_bytes:
        raise MeshError(f"BSP {name} lump at byte {offset}: {length} bytes is not a whole number of {record_bytes}-byte records")
    return offset, memoryview(data)[offset : offset + length]


_Scalar = TypeVar("_Scalar", bound=np.generic)


def _records(data: bytes, name: str, dtype: np.dtype[_Scalar]) -> tuple[int, npt.NDArray[_Scalar]]:
    offset, raw = _lump(data, name, dtype.itemsize)
    return offset, np.frombuffer(raw, dtype=dtype)


def _fault(name: str, byte: int, what: str) -> MeshError:
    return MeshError(f"BSP {name} lump at byte {byte}: {what}")


def _texture_names(data: bytes) -> list[str]:
    """Lower-case name of each miptex (dmiptexlump_t); "" for a missing one (offset -1)."""
    offset, raw = _lump(data, "textures")
    if len(raw) == 0:
        return []
    if len(raw) < 4:
        raise _fault("textures", offset, f"{len(raw)} bytes cannot hold the texture count")
    count = struct.unpack_from("<i", raw, 0)[0]
    if count < 0 or 4 + 4 * count > len(raw):
        raise _fault("textures", offset, f"{count} textures do not fit in its {len(raw)} bytes")
    names = []
    for i, at in enumerate(struct.unpack_from(f"<{count}i", raw, 4)):
        if at == -1:
            names.append("")
        elif at < 0 or at + MIPTEX_NAME_BYTES > len(raw):
            raise _fault(
                "textures", offset + 4 + 4 * i, f"texture {i} starts at lump byte {at}, outside the lump's {len(raw)} bytes"
            )
        else:
            names.append(bytes(raw[at : at + MIPTEX_NAME_BYTES]).split(b"\0", 1)[0].decode("latin-1").lower())
    return names


def _kept_texinfo(data: bytes) -> npt.NDArray[np.bool_]:
    """(n_texinfo,) bool: the texinfo's texture is level geometry (module docstring)."""
    names = _texture_names(data)
    skipped = np.array([n.startswith(_SKIPPED_PREFIXES) or any(w in n for w in _SKIPPED_WORDS) for n in names], dtype=bool)
    offset, raw = _lump(data, "texinfo", TEXINFO_BYTES)
    miptex = np.frombuffer(
        raw, dtype=np.dtype({"names": ["miptex"], "formats": ["<i4"], "offsets": [TEXINFO_MIPTEX_AT], "itemsize": TEXINFO_BYTES})
    )["miptex"]
    bad = np.flatnonzero((miptex < 0) | (miptex >= len(names)))
    if len(bad):
        raise _fault(
            "texinfo",
            offset + int(bad[0]) * TEXINFO_BYTES,
            f"texinfo {bad[0]}: texture {miptex[bad[0]]} out of range ({len(names)} textures)",
        )
    kept: npt.NDArray[np.bool_] = ~skipped[miptex]
    return kept


def _world_faces(data: bytes, fmt: _Format) -> tuple[int, int, npt.NDArray[np.void]]:
    """(faces lump offset, index of the first, records) of model 0's faces."""
    offset, models = _lump(data, "models", MODEL_BYTES)
    if len(models) == 0:
        raise _fault("models", offset, "no models, so no world model")
    first, count = struct.unpack_from("<ii", models, MODEL_FIRSTFACE_AT)
    faces_at, faces = _records(data, "faces", fmt.face)
    if first < 0 or count < 0 or first + count > len(faces):
        raise _fault(
            "models",
            offset + MODEL_FIRSTFACE_AT,
            f"model 0's faces {first}..{first + count} are out of range ({len(faces)} faces)",
        )
    return faces_at, first, faces[first : first + count]


def from_bsp(data: bytes) -> TriMesh:
    """The world model's faces of a BSP29/BSP2/2PSB map (module docstring) as a TriMesh.

    Vertices (n, 3) float64 metres, world frame, +Y up (quake_frame.points_to_world); faces (m, 3)
    int32, counter-clockwise seen from the visible side. Raises MeshError on a corrupt file or a
    world without one visible triangle.
    """
    fmt = _format(data)
    keep_texinfo = _kept_texinfo(data)
    faces_at, first, faces = _world_faces(data, fmt)
    face_index = first + np.arange(len(faces))  # in the faces lump, for messages

    def face_fault(bad: npt.NDArray[np.bool_], what: str) -> MeshError:
        i = int(face_index[np.flatnonzero(bad)[0]])
        return _fault("faces", faces_at + i * fmt.face.itemsize, f"face {i}: {what}")

    texinfo = faces["texinfo"].astype(np.int64)
    bad = (texinfo < 0) | (texinfo >= len(keep_texinfo))
    if bad.any():
        raise face_fault(bad, f"texinfo {texinfo[bad][0]} out of range ({len(keep_texinfo)} texinfos)")
    kept = keep_texinfo[texinfo]
    faces, face_index = faces[kept], face_index[kept]
    if len(faces) == 0:
        raise MeshError(f"BSP {fmt.name}: the world model has no faces that are not sky, liquid, trigger or clip")
    first_edge = faces["firstedge"].astype(np.int64)
    n_edges = faces["numedges"].astype(np.int64)
    surfedges_at, surfedges = _records(data, "surfedges", np.dtype("<i4"))
    bad = (n_edges < 3) | (first_edge < 0) | (first_edge + n_edges > len(surfedges))
    if bad.any():
        i = np.flatnonzero(bad)[0]
        raise face_fault(
            bad,
            f"surfedges {first_edge[i]}..{first_edge[i] + n_edges[i]} are not a polygon within the {len(surfedges)} surfedges",
        )
    if n_edges.sum() > len(surfedges):  # each surfedge belongs to one face; this also bounds the arrays below
        raise _fault(
            "faces", faces_at, f"the world's faces claim {n_edges.sum()} surfedges, the surfedges lump holds {len(surfedges)}"
        )
    # Each face's corners in order, one per surfedge from first_edge on.
    start = np.cumsum(n_edges) - n_edges
    corner_face = np.repeat(np.arange(len(faces)), n_edges)
    corner_surfedge = first_edge[corner_face] + np.arange(len(corner_face)) - start[corner_face]
    signed = surfedges[corner_surfedge].astype(np.int64)
    edges_at, edges = _records(data, "edges", fmt.edge)
    bad_at = np.flatnonzero(np.abs(signed) >= len(edges))
    if len(bad_at):
        raise _fault(
            "surfedges",
            surfedges_at + 4 * int(corner_surfedge[bad_at[0]]),
            f"surfedge {corner_surfedge[bad_at[0]]}: edge {signed[bad_at[0]]} out of range ({len(edges)} edges)",
        )
    edge = np.abs(signed)
    corner_vertex = np.where(signed >= 0, edges[edge, 0], edges[edge, 1]).astype(np.int64)
    _, points = _records(data, "vertexes", np.dtype(("<f4", 3)))
    bad_at = np.flatnonzero(corner_vertex >= len(points))
    if len(bad_at):
        raise _fault(
            "edges",
            edges_at + int(edge[bad_at[0]]) * fmt.edge.itemsize,
            f"edge {edge[bad_at[0]]}: vertex {corner_vertex[bad_at[0]]} out of range ({len(points)} vertexes)",
        )
    # Fan (c0, c_k+1, c_k) for k = 1..n-2: reversed, so counter-clockwise from the front.
    fans = n_edges - 2
    tri_face = np.repeat(np.arange(len(faces)), fans)
    k = 1 + np.arange(len(tri_face)) - (np.cumsum(fans) - fans)[tri_face]
    base = start[tri_face]
    triangles = corner_vertex[np.stack([base, base + k + 1, base + k], axis=1)]
    used, compact = np.unique(triangles, return_inverse=True)
    return from_arrays(points_to_world(points[used]), compact.reshape(-1, 3))


def _entity_tokens(text: bytes, offset: int) -> Iterator[tuple[int, str | None, str | None]]:
    """(byte index, word or None, brace or None) of each token of the entity text that starts at
    file byte `offset`: braces, quoted strings (no escapes, as QW/client/common.c COM_Parse) and
    bare words; // comments are skipped."""
    at, n = 0, len(text)
    while True:
        while at < n and text[at] <= 32:
            at += 1
        if text.startswith(b"//", at):
            at = text.find(b"\n", at)
            at = n if at < 0 else at
            continue
        if at >= n:
            return
        if text[at] in b"{}":
            yield at, None, chr(text[at])
            at += 1
        elif text[at] == ord('"'):
            end = text.find(b'"', at + 1)
            if end < 0:
                raise _fault("entities", offset, f"string without its closing quote at byte {offset + at}")
            yield at, text[at + 1 : end].decode("latin-1"), None
            at = end + 1
        else:
            end = at
            while end < n and text[end] > 32 and text[end] not in b'{}"':
                end += 1
            yield at, text[at:end].decode("latin-1"), None
            at = end


def bsp_entities(data: bytes) -> list[dict[str, str]]:
    """The entity lump's entities, in file order: {"classname": ..., "origin": "x y z", ...}.

    Values are the file's strings (origins in Quake units, Z up: convert with quake_frame). Text
    is decoded as Latin-1 (Quake's high characters are glyphs, not UTF-8) up to the first NUL.
    Raises MeshError with the byte offset of an unterminated entity or string or a stray token.
    """
    _format(data)
    offset, raw = _lump(data, "entities")
    text = bytes(raw).split(b"\0", 1)[0]
    entities: list[dict[str, str]] = []
    current: dict[str, str] | None = None
    key: str | None = None
    for at, word, brace in _entity_tokens(text, offset):
        if brace == "{" and current is None:
            current = {}
        elif brace == "}" and current is not None and key is None:
            entities.append(current)
            current = None
        elif brace is not None or current is None:
            raise _fault("entities", offset, f"unexpected {brace or word!r} at byte {offset + at}")
        elif key is None:
            key = word
        else:
            assert word is not None  # _entity_tokens yields a brace or a word, and this token is no brace
            current[key], key = word, None
    if current is not None:
        raise _fault("entities", offset, f"entity without its closing '}}' at byte {offset + len(text)}")
    return entities
