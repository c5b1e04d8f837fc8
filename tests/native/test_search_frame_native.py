"""camdirector._native.search_frame (native/src/search_frame_py.rs): a compiled search-mode
frame's MOTION and VISIBILITY in one call, against the separate calls it stands for.

Every call of compiled demo sessions (ANTICIPATION with its A-map, RAYCAST with ray casts) is
recorded with its inputs and the generator's state, then made again as the separate calls the
rig made before (the points carried a target at a time, ToricMotion's upright side,
SearchCore.step, Scene.visible_share_of, FramingCore.error): the same bits, the same draws.
The upright side is checked against the Python ToricMotion's on the same torus. The sessions'
recordings (tests/data/recordings/compiled/), made before the call existed, replaying bit for
bit is the end-to-end check (tests/worker/test_recordings_across_machines.py).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from camdirector import _native as native
from camdirector.demo.client import frame_updates, session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.geometry.camera import Lens
from camdirector.pipeline.toric.camera_motion import ToricMotion
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.table import SessionTable

SEARCH_FRAME = native.search_frame  # the call itself, where the sessions' is patched to check it
FRAMES = 420  # 7 s at 60 Hz of a demo scene on which both modes cut (5 and 3 times), the maps refilled after each


class _Ticking:
    """A clock that reads one more millisecond each time: laps count readings."""

    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        self.now_s += 1e-3
        return self.now_s


def _session(mode: int, check: Callable[[list[Any], Any], None]) -> int:
    """Runs a compiled demo session in `mode`, calling `check` with each search_frame call's
    arguments just before the call (the session's Scene, generator and maps as the call finds
    them) and the session's rig; answers the number of calls."""
    scene = build_demo_scene(seed=7, duration_s=FRAMES / 60.0 + 1.0)
    table = SessionTable(ServerSettings(checkpoint_store="off", frame_path="compiled"))
    table.create("s", session_request(scene, Lens(), visibility=mode))
    count = 0

    def checked(*args: Any) -> Any:
        nonlocal count
        count += 1
        check(list(args), table.get("s").session.rig)
        return SEARCH_FRAME(*args)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(native, "search_frame", checked)
        for update in frame_updates(scene, FRAMES):
            update.session_id = "s"
            table.frame(update)
    table.close_all()
    return count


def _on_a_copy(args: list[Any]) -> list[Any]:
    """The call's arguments with a copy of its generator and a clock and laps of its own, so a
    test's extra call leaves the session as it was."""
    args = list(args)
    args[10] = copy.deepcopy(args[10])
    args[18:21] = [_Ticking(), 0.0, {}]
    return args


@pytest.mark.parametrize("mode", [pb.ANTICIPATION, pb.RAYCAST], ids=["ANTICIPATION", "RAYCAST"])
def test_each_call_answers_what_the_separate_calls_answer(mode):
    motion: ToricMotion | None = None
    cuts = 0

    def check(args: list[Any], rig: Any) -> None:
        nonlocal motion, cuts
        (search, side_core, framing, scene, torus, particle, side, side_key, points_local, transforms, rng, amap) = args[:12]
        samples_local, a_world, b_world, level, time_s, dt_s = args[12:18]
        mine = _on_a_copy(args)
        answer = SEARCH_FRAME(*mine)
        # the side, by the Python stage from the same state (the compiled torus, as the rig passed it before)
        if motion is None:
            motion = ToricMotion(rig.style, rig.lens, rig.motion.settings)
        motion.side, motion._side_key = side, side_key
        upright = math.copysign(1.0, motion.preferred_place(torus)[1])
        assert (motion.side, motion._side_key) == (answer[6], answer[7])
        per_target = len(points_local) // len(transforms)
        points = np.concatenate(
            [native.carry(points_local[t * per_target : (t + 1) * per_target], tf) for t, tf in enumerate(transforms)]
        )
        twin = copy.deepcopy(rng)
        theta, phi, cut, strategy, _, moved, pose, _ = search.step(
            torus, particle, dt_s, time_s, upright, scene, points, twin, amap, level
        )
        assert (theta, phi, cut, strategy) == answer[:4]
        assert moved[:2] + moved[3:] == answer[4][:2] + answer[4][3:]
        assert np.array_equal(moved[2], answer[4][2])
        assert all(np.array_equal(x, y) for x, y in zip(pose, answer[5]))
        assert answer[8] == scene.visible_share_of(pose[0], samples_local, transforms)
        error = framing.error(pose[0], pose[1], a_world, b_world, level)
        assert answer[9] == error or (math.isnan(answer[9]) and math.isnan(error))
        assert twin.bit_generator.state == mine[10].bit_generator.state  # the call drew what the step draws
        cuts += cut

    assert _session(mode, check) == FRAMES  # every frame, the first (where the search starts) too
    assert cuts  # a cut among them


def test_the_laps_are_motion_then_visibility_on_the_clock_given():
    laps: list[dict[str, float]] = []

    def check(args: list[Any], _: Any) -> None:
        mine = _on_a_copy(args)
        mine[20] = {"motion": 2.0}
        SEARCH_FRAME(*mine)
        laps.append(mine[20])

    _session(pb.RAYCAST, check)
    # one reading after each stage, 1 ms apart on the ticking clock, from last_s 0 (its first reading is 1 ms)
    assert laps[0] == pytest.approx({"motion": 3.0, "visibility": 1.0})


def test_points_that_do_not_split_among_the_targets_are_refused():
    refusals: list[str] = []

    def check(args: list[Any], _: Any) -> None:
        if refusals:
            return
        mine = _on_a_copy(args)
        count = len(mine[8]) + 1  # more targets than points: no equal blocks
        mine[9] = [mine[9][0]] * count
        with pytest.raises(ValueError, match=f"cannot be split among {count} targets") as refused:
            SEARCH_FRAME(*mine)
        refusals.append(str(refused.value))

    _session(pb.RAYCAST, check)
    assert refusals
