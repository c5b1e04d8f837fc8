"""Recordings made on the compiled frame path (tests/data/recordings/compiled/, README.md) replay
bit for bit on any x86-64 machine: here, with no check of which machine made them, and in child
processes that play other kinds of machine (machine_kinds.py), while a recording made on the
Python path, the control, answers differently there. Also: the harness's children get the kernels
they are told to, and the script that made the recordings makes them again.

The kinds change numpy's SIMD loops, OpenBLAS's kernels and libm's FMA; what they cannot change
(Embree's ISA) the compiled TORIC frame does not use, in any visibility mode."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numpy._core._multiarray_umath import __cpu_features__

from camdirector.v1 import director_pb2 as pb
from camdirector.worker.recording import read_entries
from camdirector.worker.replay import _comparable, replay
from tests.precompute.tracks.tiny_levels import corridor
from tests.service.tracks_sessions import cli_add_level, obj_text
from tests.worker.machine_kinds import KINDS, ROOT, MachineKind, played, replay_as

RECORDINGS = Path(__file__).resolve().parents[1] / "data" / "recordings"
COMPILED = RECORDINGS / "compiled"
# each TORIC visibility mode's: the old recordings' inputs, and a tumbling target's (README.md)
MODES = ("reactive", "raycast", "anticipation")
COMPILED_NAMES = ["framing_only", "tumbling", *MODES, *(f"tumbling_{mode}" for mode in MODES)]
SOURCES = {"framing_only": "../framing_only.cdrec"} | {mode: f"../{mode}.cdrec" for mode in MODES}  # where the inputs come from
REMAKE = ROOT / "scripts" / "remake_recording.py"


def _kind(kind: MachineKind) -> MachineKind:
    if not kind.playable():
        pytest.skip(f"this CPU cannot run {kind.name}'s kernels ({', '.join(kind.needs)})")
    return kind


@pytest.mark.parametrize("name", COMPILED_NAMES)
def test_a_compiled_recording_replays_bit_for_bit_here(name, tmp_path):
    path = COMPILED / f"{name}.cdrec"
    kinds = [entry.WhichOneof("entry") for entry in read_entries(path)]
    assert kinds[0] == "create" and kinds.count("camera") == 240  # a real session, not an empty file
    report = replay(path, data_dir=tmp_path, frame_path="compiled").as_dict()
    assert report == {"frames": 240, "identical": 240, "first_mismatch": None, "ok": True}


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.name)
def test_compiled_recordings_replay_bit_for_bit_on_every_kind_of_machine(kind, tmp_path):
    kind = _kind(kind)
    for name in COMPILED_NAMES:
        report = replay_as(kind, COMPILED / f"{name}.cdrec", "compiled", tmp_path)
        assert report["ok"] and report["frames"] == 240, (name, report)


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.name)
def test_a_child_gets_the_kernels_of_its_kind(kind):
    """numpy's dispatched targets are the kind's, OpenBLAS runs its kernels, and libm's sin is
    another one exactly when the kind leaves out the FMA this machine has."""
    kind = _kind(kind)
    here, there = played(None), played(kind)
    assert there["numpy"] == [t for t in here["numpy"] if t in kind.numpy_targets]
    assert there["openblas"] is not None and there["openblas"].lower() == kind.openblas_core.lower()
    assert (there["libm_sin"] != here["libm_sin"]) == (__cpu_features__["FMA3"] and not kind.fma)


def test_the_python_path_answers_differently_on_another_kind_of_machine(tmp_path):
    """The control: the tumbling inputs recorded here on the Python path replay bit for bit here,
    and not on a kind without FMA (OpenBLAS's and libm's kernels round otherwise): the harness
    shows machine dependence where there is some."""
    if not __cpu_features__["FMA3"]:
        pytest.skip("this CPU has no FMA: the kinds without it are this machine's own kernels")
    python = tmp_path / "tumbling_python.cdrec"
    subprocess.run(
        [sys.executable, str(REMAKE), str(COMPILED / "tumbling.cdrec"), str(python), "--frame-path", "python"], check=True
    )
    assert replay_as(None, python, "python", tmp_path)["ok"]
    for kind in KINDS:
        if kind.playable() and not kind.fma:
            report = replay_as(kind, python, "python", tmp_path)
            assert not report["ok"], (kind.name, report)


@pytest.mark.parametrize("name", COMPILED_NAMES)
def test_the_script_makes_the_compiled_recordings_again(name, tmp_path):
    """scripts/remake_recording.py, from the inputs README.md names, answers what was recorded."""
    source = SOURCES.get(name, f"{name}.cdrec")
    again = tmp_path / f"{name}.cdrec"
    subprocess.run([sys.executable, str(REMAKE), str(COMPILED / source), str(again), "--frame-path", "compiled"], check=True)

    def answers(path: Path) -> list[bytes]:
        return [_comparable(e.camera) for e in read_entries(path) if e.WhichOneof("entry") == "camera"]

    assert answers(again) == answers(COMPILED / f"{name}.cdrec")


def _pose_apart(a: bytes, b: bytes) -> tuple[float, bytes, bytes]:
    """The largest difference between two answers' pose floats (position m, rotation, fov deg),
    and each answer without its pose."""
    first, second = pb.CameraUpdate.FromString(a), pb.CameraUpdate.FromString(b)
    floats = [
        np.array([p.position.x, p.position.y, p.position.z, p.rotation.x, p.rotation.y, p.rotation.z, p.rotation.w])
        for p in (first.pose, second.pose)
    ]
    apart = float(np.abs(floats[0] - floats[1]).max(initial=0.0))
    apart = max(apart, abs(first.pose.vertical_fov_deg - second.pose.vertical_fov_deg))
    first.ClearField("pose")
    second.ClearField("pose")
    return apart, first.SerializeToString(deterministic=True), second.SerializeToString(deterministic=True)


@pytest.mark.parametrize("name", ["match", "tracks"])
def test_a_rig_without_a_compiled_twin_answers_the_same_bits_on_both_paths(name, tmp_path):
    """TRACKS and MATCH run in Python on either path (rigs.runs_compiled): the inputs of their
    recordings (tests/data/recordings/, made elsewhere) answer here alike on both, bit for bit but
    for MATCH's poses, which agree within 1e-9 (issue 43's bar) with every other field the same
    bits (cuts, shots, visibility): the compiled decoder normalises a quaternion with its squares
    summed in order, numpy's norm by the CPU's kernel (worker/codec.py), and a camera through a
    player's eyes (first_person.py) carries the player's rotation, last bit and all, into its pose."""
    if name == "tracks":
        level_file = tmp_path / "corridor.obj"
        level_file.write_text(obj_text(corridor()))
        cli_add_level(tmp_path, "corridor", level_file)
    answers: dict[str, list[bytes]] = {"python": [], "compiled": []}
    for frame_path, kept in answers.items():
        replay(RECORDINGS / f"{name}.cdrec", lambda _, got, kept=kept: kept.append(_comparable(got)), tmp_path, frame_path)
    assert len(answers["python"]) >= 120 and len(answers["compiled"]) == len(answers["python"])
    if name == "tracks":
        assert answers["compiled"] == answers["python"]
        return
    for compiled, python in zip(answers["compiled"], answers["python"]):
        apart, compiled_rest, python_rest = _pose_apart(compiled, python)
        assert apart <= 1e-9 and compiled_rest == python_rest


def test_frames_sent_as_states_replay_bit_for_bit_on_every_kind_of_machine(tmp_path):
    """The tumbling inputs with their transforms sent as `states`, not `packed_transforms`,
    recorded here on the compiled path, replayed in a child of each kind: the compiled wire
    decoder (worker/codec.py frame_from_wire) normalises their quaternions in one order, where the
    Python codec's np.linalg.norm is OpenBLAS's dot (it failed from frame 9 under Haswell's and
    Sandy Bridge's kernels before the decoder)."""
    if not __cpu_features__["FMA3"]:
        pytest.skip("this CPU has no FMA: the kinds without it may be its own kernels, and show nothing")
    states = tmp_path / "tumbling_states.cdrec"
    command = [sys.executable, str(REMAKE), str(COMPILED / "tumbling.cdrec"), str(states), "--frame-path", "compiled", "--states"]
    subprocess.run(command, check=True)
    assert replay_as(None, states, "compiled", tmp_path)["ok"]
    for kind in KINDS:
        if kind.playable():
            assert replay_as(kind, states, "compiled", tmp_path)["ok"], kind.name
