"""Quake BSP maps (geometry/bsp.py): a room written here byte by byte as BSP29, BSP2 and 2PSB, the
real maps of tests/data/real_maps (SOURCES.md) with their spawn points standing on floors, corrupt
and truncated files, and `camdirector level add` of a .bsp end to end."""

from __future__ import annotations

import gzip
import re
import struct
from pathlib import Path

import numpy as np
import pytest
import trimesh

from camdirector.geometry.bsp import HEADER_BYTES, LUMP_NAMES, bsp_entities, from_bsp
from camdirector.geometry.meshes import MeshError
from camdirector.geometry.quake_frame import M_PER_UNIT, PLAYER_RADIUS_M, points_to_world
from camdirector.geometry.raycast import RayScene
from camdirector.precompute.tracks.level_mesh import load_level_mesh
from camdirector.precompute.tracks.registry import LevelRegistry
from tests.service.tracks_sessions import cli_add_level

REAL_MAPS = Path(__file__).resolve().parents[1] / "data" / "real_maps"
# name -> (world triangles, bounds min (3,) m, bounds max (3,) m), as SOURCES.md lists them.
REAL = {
    "dm2": (12486, (38.0, -5.75, -11.0), (94.0, 18.0, 81.0)),
    "bravado": (4866, (-21.75, -0.5, -40.25), (32.0, 18.0, 13.0)),
    "frobodm2": (12605, (36.0, -5.75, -11.0), (94.0, 18.0, 80.0)),
    "q3dm6qw": (28267, (-51.5, -6.5, -42.0), (32.75, 24.0, 41.5)),
}
FORMATS = {"BSP29": struct.pack("<i", 29), "BSP2": b"BSP2", "2PSB": b"2PSB"}

# -- a room written as a BSP file -------------------------------------------------------------
# A box 256 x 128 x 128 Quake units (8 x 4 x 4 m). Each face: its texture and its corners as Quake
# stores them, clockwise seen from the side a player sees (from inside the room).
X, Y, Z = 256.0, 128.0, 128.0
WORLD_FACES = [
    ("floor", [(0, 0, 0), (0, Y, 0), (X, Y, 0), (X, 0, 0)]),
    ("sky1", [(0, 0, Z), (X, 0, Z), (X, Y, Z), (0, Y, Z)]),  # ceiling: sky, left out
    ("wall", [(0, 0, 0), (X, 0, 0), (X, 0, Z), (0, 0, Z)]),  # y = 0, seen from +y
    ("wall", [(0, Y, 0), (0, Y, Z), (X, Y, Z), (X, Y, 0)]),  # y = Y, seen from -y
    ("wall", [(0, 0, 0), (0, 0, Z), (0, Y, Z), (0, Y, 0)]),  # x = 0, seen from +x
    # x = X, seen from -x: a pentagon with a corner on an edge (as qbsp leaves T-junctions), 3 triangles
    ("WALL", [(X, 0, 0), (X, Y, 0), (X, Y, 64), (X, Y, Z), (X, 0, Z)]),
    ("*water0", [(0, 0, 32), (0, 64, 32), (64, 64, 32), (64, 0, 32)]),  # liquid, left out
    ("trigger", [(96, 0, 0), (96, 0, 64), (96, 64, 64), (96, 64, 0)]),  # tool texture, left out
    ("Clip", [(128, 0, 0), (128, 0, 64), (128, 64, 64), (128, 64, 0)]),  # tool texture, left out
]
DOOR_FACES = [("door", [(100, 50, 0), (100, 50, 90), (100, 80, 90), (100, 80, 0)])]  # model 1: not the world
ENTITIES = (
    b'{\n"classname" "worldspawn"\n"message" "Test room"\n}\n'
    b"// a comment, as COM_Parse allows\n"
    b'{\n"classname" "info_player_deathmatch"\n"origin" "64 32 24"\n"angle" "90"\n}\n'
    b'{ "classname" "func_door" "model" "*1" }\n\0'
)
EXPECTED_ENTITIES = [
    {"classname": "worldspawn", "message": "Test room"},
    {"classname": "info_player_deathmatch", "origin": "64 32 24", "angle": "90"},
    {"classname": "func_door", "model": "*1"},
]


def write_bsp(magic: bytes = FORMATS["BSP29"], world=WORLD_FACES, door=DOOR_FACES, entities=ENTITIES) -> bytes:
    """A BSP file holding only what a level needs: textures, texinfo, faces, edges, surfedges,
    vertexes, models (world, door) and the entity text; the other lumps are empty."""
    wide = magic != FORMATS["BSP29"]
    names = sorted({name for name, _ in world + door})
    vertexes: list[tuple] = []
    edges = [(0, 0)]  # edge 0 is never used (a surfedge's sign needs it)
    surfedges, faces = [], []
    for face_number, (name, corners) in enumerate(world + door):
        first, base = len(surfedges), len(vertexes)
        vertexes += corners
        for i in range(len(corners)):
            a, b = base + i, base + (i + 1) % len(corners)
            # Every other edge stored backwards, walked with a negative surfedge.
            if (face_number + i) % 2:
                edges.append((b, a))
                surfedges.append(-(len(edges) - 1))
            else:
                edges.append((a, b))
                surfedges.append(len(edges) - 1)
        face_fmt = "<iiiii4Bi" if wide else "<hhihh4Bi"
        faces.append(struct.pack(face_fmt, 0, 0, first, len(corners), names.index(name), 0, 0, 0, 0, -1))
    miptex = [struct.pack("<16sII4I", name.encode(), 16, 16, 0, 0, 0, 0) for name in names]
    table = 4 + 4 * len(names)
    textures = struct.pack(f"<i{len(names)}i", len(names), *(table + 40 * i for i in range(len(names)))) + b"".join(miptex)
    texinfo = b"".join(struct.pack("<8fii", *([0.0] * 8), i, 0) for i in range(len(names)))

    def model(first, count):
        return struct.pack("<9f4iiii", *([0.0] * 9), 0, 0, 0, 0, 0, first, count)

    lumps = {
        "entities": entities,
        "textures": textures,
        "texinfo": texinfo,
        "faces": b"".join(faces),
        "edges": b"".join(struct.pack("<II" if wide else "<HH", *e) for e in edges),
        "surfedges": struct.pack(f"<{len(surfedges)}i", *surfedges),
        "vertexes": b"".join(struct.pack("<3f", *v) for v in vertexes),
        "models": model(0, len(world)) + model(len(world), len(door)),
    }
    body, directory = b"", []
    for name in LUMP_NAMES:
        data = lumps.get(name, b"")
        directory.append((HEADER_BYTES + len(body), len(data)))
        body += data + b"\0" * (-len(data) % 4)
    return magic + b"".join(struct.pack("<ii", *d) for d in directory) + body


def expected_triangles() -> list[tuple]:
    """The visible world faces' fans in metres, world axes, counter-clockwise from inside."""
    triangles = []
    for name, corners in WORLD_FACES:
        if name.lower().startswith(("sky", "*")) or name.lower() in ("trigger", "clip"):
            continue
        c = points_to_world(np.array(corners, dtype=float))
        triangles += [(c[0], c[k + 1], c[k]) for k in range(1, len(c) - 1)]
    return triangles


def canonical(triangles) -> set[tuple]:
    """Triangles as a set, each turned (keeping its winding) to start at its smallest corner."""
    out = set()
    for tri in triangles:
        corners = [tuple(np.round(np.asarray(p, dtype=float), 9)) for p in tri]
        k = corners.index(min(corners))
        out.add(tuple(corners[k:] + corners[:k]))
    return out


def lump_directory(data: bytes) -> dict[str, tuple[int, int]]:
    return {name: struct.unpack_from("<ii", data, 4 + 8 * i) for i, name in enumerate(LUMP_NAMES)}


def with_lump_entry(data: bytes, name: str, offset: int, length: int) -> bytes:
    at = 4 + 8 * LUMP_NAMES.index(name)
    return data[:at] + struct.pack("<ii", offset, length) + data[at + 8 :]


def patched(data: bytes, at: int, fmt: str, *values) -> bytes:
    out = bytearray(data)
    struct.pack_into(fmt, out, at, *values)
    return bytes(out)


# -- the hand-built room ----------------------------------------------------------------------


@pytest.mark.parametrize("fmt", FORMATS)
def test_the_room_gives_exactly_its_visible_walls_in_metres_y_up(fmt):
    mesh = from_bsp(write_bsp(FORMATS[fmt]))
    got = canonical(mesh.vertices[mesh.faces])
    want = canonical(expected_triangles())
    assert got == want and mesh.triangle_count == 4 * 2 + 3 == len(want)
    # 256 x 128 x 128 units: x 0..8 m, y (Quake z, up) 0..4 m, z (-Quake y) -4..0 m.
    np.testing.assert_allclose(mesh.vertices.min(axis=0), [0.0, 0.0, -4.0])
    np.testing.assert_allclose(mesh.vertices.max(axis=0), [8.0, 4.0, 0.0])


def test_every_kept_triangle_faces_into_the_room():
    """Counter-clockwise from the visible side: normals point inward, the floor's straight up."""
    mesh = from_bsp(write_bsp())
    tri = mesh.vertices[mesh.faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    centre = np.array([4.0, 2.0, -2.0])
    assert np.all(np.einsum("ij,ij->i", normal, centre - tri.mean(axis=1)) > 0)
    floor = np.all(np.abs(tri[:, :, 1]) < 1e-12, axis=1)
    assert floor.sum() == 2 and np.all(normal[floor, 1] > 0)


def test_entities_in_file_order_with_comments_skipped():
    assert bsp_entities(write_bsp()) == EXPECTED_ENTITIES
    assert bsp_entities(write_bsp(b"BSP2")) == EXPECTED_ENTITIES


def test_a_world_of_sky_and_water_only_is_refused():
    data = write_bsp(world=[WORLD_FACES[1], WORLD_FACES[6]])
    with pytest.raises(MeshError, match="no faces that are not sky"):
        from_bsp(data)


# -- bad files ----------------------------------------------------------------------------------


def test_a_wrong_magic_or_version_names_the_header():
    data = write_bsp()
    for magic in (struct.pack("<i", 30), struct.pack("<i", 38), b"IBSP", b"bsp2"):
        with pytest.raises(MeshError, match=r"BSP header at byte 0: version/magic"):
            from_bsp(magic + data[4:])
    with pytest.raises(MeshError, match="shorter than the 124-byte header"):
        from_bsp(data[: HEADER_BYTES - 1])


@pytest.mark.parametrize("name", ["faces", "edges", "surfedges", "vertexes", "textures", "texinfo", "models"])
def test_a_lump_outside_the_file_names_the_lump_and_its_bytes(name):
    data = write_bsp()
    offset, length = lump_directory(data)[name]
    with pytest.raises(
        MeshError,
        match=rf"BSP {name} lump \(header byte {4 + 8 * LUMP_NAMES.index(name)}\): "
        rf"bytes {len(data) - 4}\.\.{len(data) - 4 + length} lie outside",
    ):
        from_bsp(with_lump_entry(data, name, len(data) - 4, length))
    with pytest.raises(MeshError, match=rf"BSP {name} lump"):
        from_bsp(with_lump_entry(data, name, -8, length))


def test_a_lump_of_part_records_is_refused():
    data = write_bsp()
    offset, length = lump_directory(data)["faces"]
    with pytest.raises(MeshError, match=rf"BSP faces lump at byte {offset}: {length - 2} bytes is not a whole number of 20-byte"):
        from_bsp(with_lump_entry(data, "faces", offset, length - 2))


def test_indices_out_of_range_name_the_lump_and_the_record_byte():
    data = write_bsp()
    lumps = lump_directory(data)
    faces_at, edges_at, surf_at, models_at, texinfo_at = (
        lumps[n][0] for n in ("faces", "edges", "surfedges", "models", "texinfo")
    )
    # face 0's texinfo (dface_t offset 10) past the texinfos
    with pytest.raises(MeshError, match=rf"BSP faces lump at byte {faces_at}: face 0: texinfo 999 out of range"):
        from_bsp(patched(data, faces_at + 10, "<h", 999))
    # face 2's surfedges run past the lump (firstedge at offset 4 of its 20 bytes)
    with pytest.raises(MeshError, match=rf"BSP faces lump at byte {faces_at + 40}: face 2: surfedges 100000\.\."):
        from_bsp(patched(data, faces_at + 40 + 4, "<i", 100000))
    # surfedge 3 names an edge that does not exist
    with pytest.raises(MeshError, match=rf"BSP surfedges lump at byte {surf_at + 12}: surfedge 3: edge -70000 out"):
        from_bsp(patched(data, surf_at + 12, "<i", -70000))
    # edge 1's first vertex out of range
    with pytest.raises(MeshError, match=rf"BSP edges lump at byte {edges_at + 4}: edge 1: vertex 60000 out of range"):
        from_bsp(patched(data, edges_at + 4, "<H", 60000))
    # model 0's faces beyond the faces lump
    with pytest.raises(MeshError, match=rf"BSP models lump at byte {models_at + 56}: model 0's faces 0\.\.500"):
        from_bsp(patched(data, models_at + 60, "<i", 500))
    # texinfo 1's texture index past the textures
    with pytest.raises(MeshError, match=rf"BSP texinfo lump at byte {texinfo_at + 40}: texinfo 1: texture 77 out"):
        from_bsp(patched(data, texinfo_at + 40 + 32, "<i", 77))
    # a BSP2 file has 32-bit edges: the same fault is found there
    wide = write_bsp(b"BSP2")
    with pytest.raises(MeshError, match=r"BSP edges lump at byte \d+: edge 1: vertex 4000000000 out of range"):
        from_bsp(patched(wide, lump_directory(wide)["edges"][0] + 8, "<I", 4000000000))


def test_bad_entity_text_names_the_byte():
    head = b'{\n"classname" "worldspawn"\n}\n'
    for text, what in [
        (head + b'{ "origin" "1 2 3\n', "string without its closing quote"),
        (head + b'{ "origin" "1 2 3"\n', "entity without its closing '}'"),
        (head + b'"stray" "pair"\n', "unexpected 'stray'"),
        (head + b"{ { }\n", "unexpected '{'"),
        (head + b'{ "key" }\n', "unexpected '}'"),
    ]:
        data = write_bsp(entities=text)
        at = lump_directory(data)["entities"][0]
        with pytest.raises(MeshError, match=rf"BSP entities lump at byte {at}: {re.escape(what)}.* at byte \d+"):
            bsp_entities(data)


def test_random_damage_raises_mesh_error_or_gives_a_mesh():
    """Nothing but MeshError escapes, whatever bytes are flipped (header and records alike)."""
    rng = np.random.default_rng(7)
    for fmt in FORMATS.values():
        good = write_bsp(fmt)
        for _ in range(300):
            data = bytearray(good)
            for at in rng.integers(0, len(data), size=rng.integers(1, 6)):
                data[at] = int(rng.integers(0, 256))
            for read in (from_bsp, bsp_entities):
                try:
                    read(bytes(data))
                except MeshError:
                    pass


# -- the real maps ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def real_maps() -> dict[str, bytes]:
    return {name: gzip.decompress((REAL_MAPS / f"{name}.bsp.gz").read_bytes()) for name in REAL}


def test_only_the_listed_maps_are_there_and_sources_lists_them():
    assert sorted(p.name for p in REAL_MAPS.glob("*.bsp.gz")) == sorted(f"{n}.bsp.gz" for n in REAL)
    sources = (REAL_MAPS / "SOURCES.md").read_text()
    for name, (triangles, _, _) in REAL.items():
        assert f"{name}.bsp" in sources and f"{triangles}" in sources


@pytest.mark.parametrize("name", REAL)
def test_a_real_map_loads_with_its_triangles_and_bounds(real_maps, name):
    triangles, low, high = REAL[name]
    mesh = from_bsp(real_maps[name])
    assert mesh.triangle_count == triangles
    np.testing.assert_allclose(mesh.vertices.min(axis=0), low)
    np.testing.assert_allclose(mesh.vertices.max(axis=0), high)


@pytest.mark.parametrize("name", REAL)
def test_every_deathmatch_spawn_stands_on_a_floor_under_a_free_ceiling(real_maps, name):
    """A spawn's origin is 24 units (0.75 m) above its feet and 32 (1 m) below the top of its
    16-unit-radius box: so a floor under the box within 1.5 m and no ceiling over it within 1 m,
    cast from the origin and from just inside the box's four corners (a box may stand on a ledge
    with one side). Wrong axes or scale put the spawns in the void or the walls."""
    mesh = from_bsp(real_maps[name])
    spawns = [e for e in bsp_entities(real_maps[name]) if e.get("classname") == "info_player_deathmatch"]
    assert len(spawns) >= 4
    origins = points_to_world(np.array([[float(v) for v in e["origin"].split()] for e in spawns]))
    inset = PLAYER_RADIUS_M - M_PER_UNIT
    footprint = np.array([[0, 0, 0], [1, 0, 1], [1, 0, -1], [-1, 0, 1], [-1, 0, -1]]) * inset
    points = (origins[:, None, :] + footprint[None]).reshape(-1, 3)
    scene = RayScene([mesh])
    down = scene.first_hit(points, np.tile([0.0, -1.0, 0.0], (len(points), 1))).reshape(len(origins), -1)
    up = scene.first_hit(points, np.tile([0.0, 1.0, 0.0], (len(points), 1))).reshape(len(origins), -1)
    assert np.all(down.min(axis=1) <= 1.5), f"spawns without a floor: {np.flatnonzero(down.min(axis=1) > 1.5)}"
    assert np.all(up.min(axis=1) >= 1.0), f"spawns under a low ceiling: {np.flatnonzero(up.min(axis=1) < 1.0)}"
    # The floor right under a spawn faces up (the winding is the player's side).
    centre = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    _, ray, tri = centre.ray.intersects_location(origins, np.tile([0.0, -1.0, 0.0], (len(origins), 1)), multiple_hits=False)
    assert len(ray) >= len(origins) // 2 and np.all(centre.face_normals[tri, 1] > 0.7)


def test_a_real_map_cut_short_or_with_a_bad_lump_raises_mesh_error(real_maps):
    data = real_maps["dm2"]
    lumps = lump_directory(data)
    read = ("entities", "textures", "texinfo", "faces", "edges", "surfedges", "vertexes", "models")
    end = max(lumps[n][0] + lumps[n][1] for n in read)
    for length in np.linspace(0, end - 1, 25).astype(int):
        with pytest.raises(MeshError, match=r"BSP (header|\w+ lump)"):
            from_bsp(data[:length])
    entities_end = sum(lumps["entities"])
    for length in (10, HEADER_BYTES, entities_end - 1):
        with pytest.raises(MeshError, match=r"BSP (header|entities lump)"):
            bsp_entities(data[:length])
    faces_at, faces_len = lumps["faces"]
    with pytest.raises(MeshError, match=rf"BSP faces lump \(header byte 60\): bytes {faces_at}\.\.{faces_at + 2 * len(data)}"):
        from_bsp(with_lump_entry(data, "faces", faces_at, 2 * len(data)))
    # a surfedge of the world pointing past the edges
    surf_at = lumps["surfedges"][0]
    with pytest.raises(MeshError, match=rf"BSP surfedges lump at byte {surf_at + 4 * 10}"):
        from_bsp(patched(data, surf_at + 4 * 10, "<i", 2_000_000_000))


def test_a_bsp_level_loads_in_metres_and_scale_still_multiplies(tmp_path, real_maps):
    path = tmp_path / "bravado.BSP"
    path.write_bytes(real_maps["bravado"])
    mesh = load_level_mesh(path)
    np.testing.assert_allclose(mesh.vertices.max(axis=0), REAL["bravado"][2])
    np.testing.assert_allclose(load_level_mesh(path, 2.0).vertices, 2.0 * mesh.vertices)
    bad = tmp_path / "broken.bsp"
    bad.write_bytes(b"IBSP" + bytes(200))
    with pytest.raises(MeshError, match="version/magic"):
        load_level_mesh(bad)


def test_level_add_of_dm2_end_to_end(tmp_path, real_maps):
    """`camdirector level add dm2 dm2.bsp --data-dir DIR` in a child process; the level loads,
    its level mesh is the map's world and its floors made a navigation mesh."""
    level_file = tmp_path / "dm2.bsp"
    level_file.write_bytes(real_maps["dm2"])
    record = cli_add_level(tmp_path / "data", "dm2", level_file)
    assert record["name"] == "dm2" and record["m_per_unit"] == 1.0
    assert record["counts"]["level_triangles"] == REAL["dm2"][0] and record["counts"]["nodes"] > 0
    with LevelRegistry(tmp_path / "data") as registry:
        artifact = registry.load("dm2")
    assert len(artifact.level_faces) == REAL["dm2"][0] and len(artifact.navmesh_faces) > 1000
    np.testing.assert_allclose(artifact.level_vertices.max(axis=0), REAL["dm2"][2])
