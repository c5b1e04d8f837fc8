"""The level registry (precompute/tracks/registry.py), every test on both of its indexes: SQLite in
the data directory and a table in PostgreSQL (a fresh database per test). Records survive a
reopen, a replace leaves one artifact file, a taken name without replace is refused by the index
(LevelExists), and two registries over one index and one folder (two nodes) see each other's
levels and add one name once."""

from __future__ import annotations

import threading

import pytest

from camdirector.precompute.tracks.registry import LevelExists, LevelRegistry, PostgresLevelIndex, SqliteLevelIndex

from .tiny_levels import corridor, l_room


def obj_file(path, mesh):
    path.write_text(
        "".join(f"v {x} {y} {z}\n" for x, y, z in mesh.vertices)
        + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces)
    )
    return path


@pytest.fixture
def open_registry(tmp_path, records_url):
    """Opens registries over one data folder and one index (as a cluster's nodes do), closed after."""
    opened = []

    def make() -> LevelRegistry:
        opened.append(LevelRegistry(tmp_path / "data", records_url))
        return opened[-1]

    yield make
    for registry in opened:
        registry.close()


@pytest.fixture
def levels(tmp_path):
    return {"corridor": obj_file(tmp_path / "corridor.obj", corridor()), "room": obj_file(tmp_path / "room.obj", l_room())}


def artifact_files(registry) -> list[str]:
    return sorted(p.name for p in registry.levels_dir.glob("*.npz"))


def test_the_index_is_the_one_the_url_names(open_registry, records_url):
    registry = open_registry()
    assert isinstance(registry.index, PostgresLevelIndex if records_url else SqliteLevelIndex)
    assert (registry.levels_dir / "index.sqlite3").exists() == (not records_url)


def test_survives_a_reopen_replaces_and_deletes(open_registry, levels):
    first = open_registry()
    record = first.add_level("corridor", levels["corridor"], scale=1.0, agent_height_m=1.8)
    assert record.counts["nodes"] > 0 and record.agent_height_m == 1.8 and record.m_per_unit == 1.0
    assert record.artifact_path.parent == first.levels_dir and record.source_path == str(levels["corridor"].resolve())
    again = open_registry()
    assert [r.name for r in again.list()] == ["corridor"]
    assert again.get("corridor") == record
    assert len(again.load("corridor").nodes_world) == record.counts["nodes"]
    replaced = first.add_level("corridor", levels["room"], scale=1.0)  # replaced: one file left
    assert artifact_files(first) == [replaced.artifact_path.name] != [record.artifact_path.name]
    assert again.get("corridor").source_path.endswith("room.obj")
    assert again.delete("corridor") and again.list() == [] and not again.delete("corridor")
    assert artifact_files(first) == [] and first.get("corridor") is None
    with pytest.raises(KeyError):
        first.load("corridor")
    with pytest.raises(ValueError):
        again.add_level("../bad", levels["corridor"])


def test_lists_by_name(open_registry, levels):
    registry = open_registry()
    for name in ("b.level", "A-1", "a_2"):
        registry.add_level(name, levels["corridor"])
    assert [r.name for r in registry.list()] == sorted(["b.level", "A-1", "a_2"])


def test_a_taken_name_without_replace_is_refused_and_leaves_nothing(open_registry, levels):
    registry = open_registry()
    first = registry.add_level("corridor", levels["corridor"], replace=False)
    with pytest.raises(LevelExists, match="'corridor' exists"):
        open_registry().add_level("corridor", levels["room"], replace=False)
    assert registry.get("corridor") == first and artifact_files(registry) == [first.artifact_path.name]


def test_two_registries_adding_one_name_at_once_give_one_level(open_registry, levels):
    """Two nodes (two registries over one index and folder) add one name at the same moment: the
    index takes one, the other gets LevelExists, and one artifact file is left."""
    nodes = [open_registry(), open_registry()]
    start = threading.Barrier(2)
    outcomes: list = [None, None]

    def add(i: int) -> None:
        start.wait()
        try:
            outcomes[i] = nodes[i].add_level("arena", levels["corridor" if i == 0 else "room"], replace=False)
        except LevelExists as exc:
            outcomes[i] = exc

    threads = [threading.Thread(target=add, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    won = [o for o in outcomes if not isinstance(o, LevelExists)]
    assert len(won) == 1 and sum(isinstance(o, LevelExists) for o in outcomes) == 1, outcomes
    for node in nodes:
        assert node.get("arena") == won[0]
    assert artifact_files(nodes[0]) == [won[0].artifact_path.name]


def test_two_registries_replacing_at_once_leave_one_file(open_registry, levels):
    nodes = [open_registry(), open_registry()]
    nodes[0].add_level("arena", levels["corridor"])
    start = threading.Barrier(2)
    threads = [threading.Thread(target=lambda n=n: (start.wait(), n.add_level("arena", levels["room"]))) for n in nodes]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert artifact_files(nodes[0]) == [nodes[1].get("arena").artifact_path.name]


def test_each_tenant_has_its_own_names(open_registry, levels):
    """Two tenants' "arena" side by side; tenant `default` keeps plain names and files at the top
    of the levels folder, another tenant's are in its own folder; no tenant reads, loads or
    removes another's, not even by writing its qualified name."""
    registry = open_registry()
    ours = registry.add_level("arena", levels["corridor"])
    theirs = registry.add_level("arena", levels["room"], tenant="acme")
    assert (ours.name, ours.tenant, theirs.name, theirs.tenant) == ("arena", "default", "arena", "acme")
    assert ours.artifact_path.parent == registry.levels_dir and ours.artifact_path.name.startswith("arena.")
    assert theirs.artifact_path.parent == registry.levels_dir / "acme"
    again = open_registry()
    assert again.get("arena", "acme") == theirs and again.get("arena") == ours
    assert [r.source_path for r in again.list("acme")] == [str(levels["room"].resolve())]
    assert [r.tenant for r in again.list()] == ["default"] and again.list("beta") == []
    assert again.get("arena", "beta") is None and again.get("acme/arena") is None
    assert not again.delete("arena", "beta") and not again.delete("acme/arena")
    with pytest.raises(KeyError):
        again.load("arena", "beta")
    assert len(again.load("arena", "acme").nodes_world) == theirs.counts["nodes"]
    with pytest.raises(ValueError):
        again.add_level("arena", levels["room"], tenant="Not A Tenant")
    assert again.delete("arena", "acme") and again.get("arena", "acme") is None and again.get("arena") == ours
    assert not theirs.artifact_path.exists() and ours.artifact_path.exists()
