"""camdirector._native's TORIC FRAMING and MOTION stages (native/src/framing.rs, motion.rs) against
their Python twins, pipeline/toric/framing.py's Framing and camera_motion.py's ToricMotion: each
compiled method agrees with the Python one over random valid inputs (metres within 1e-9 m, angles
within 1e-9 rad, the same flags); driven through the same long moving scenes (the demo scene's
walker, alone and with a second target; random frame gaps, pauses, a stop, jumps, a style change,
coinciding and degenerate targets), every frame agrees and the state kept between frames does not
drift; and the same inputs give the same bits."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from camdirector import _native as native
from camdirector.demo.scene import build_demo_scene
from camdirector.geometry import toric
from camdirector.geometry.camera import CameraPose, Lens
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.style import Style
from camdirector.pipeline.toric.camera_motion import MotionSettings, ToricMotion, pose_on_torus
from camdirector.pipeline.toric.frame import ToricFrame
from camdirector.pipeline.toric.framing import Framing, FramingSettings

TOL = 1e-9  # metres for positions, radians for angles, unit for quaternions and screen errors
FAST = settings(max_examples=150, derandomize=True, deadline=None, database=None)

coord = st.floats(-100.0, 100.0)
point = st.tuples(coord, coord, coord).map(np.array)
offset = st.tuples(st.floats(-8.0, 8.0), st.floats(-3.0, 3.0), st.floats(-8.0, 8.0)).map(np.array)
# B from A: not straight above or below, where the torus is symmetric about world up and both
# halves are equally upright (the tie of `styles`)
ab_offset = offset.filter(lambda o: math.hypot(o[0], o[2]) > 0.05)
quaternion = (
    st.tuples(*[st.floats(-1.0, 1.0)] * 4).filter(lambda q: math.hypot(*q) > 0.1).map(lambda q: np.array(q) / math.hypot(*q))
)
screen = st.tuples(st.floats(-0.9, 0.9), st.floats(-0.9, 0.9))
lenses = st.builds(Lens, vertical_fov_deg=st.floats(20.0, 100.0), aspect=st.floats(0.6, 2.4))
dts = st.one_of(st.just(0.0), st.floats(0.001, 0.05), st.floats(0.05, 1.5))


@st.composite
def styles(draw) -> Style:
    """A valid Style with every field the two stages read drawn. Not drawn: screen points one
    above the other, or phi 0 or 180 degrees. There both halves of the torus are equally upright
    (mirror images, or the same place), so MOTION's first choice of side is a tie that the last
    bit of sin and cos decides, differently in any two libms."""
    sa, sb = draw(screen), draw(screen)
    assume(math.dist(sa, sb) > 0.05 and abs(sa[0] - sb[0]) > 0.05)
    return Style(
        screen_a=sa,
        screen_b=sb,
        gaze_room_m=draw(st.floats(0.05, 20.0)),
        preferred_theta_ratio=draw(st.floats(0.02, 0.98)),
        preferred_phi_deg=draw(st.floats(1.0, 179.0)),
        response_time_s=draw(st.floats(0.02, 5.0)),
        max_speed_m_s=draw(st.floats(0.1, 50.0)),
        max_accel_m_s2=draw(st.floats(0.1, 100.0)),
    )


def max_diff(got, want) -> float:
    got, want = np.asarray(got, dtype=np.float64), np.asarray(want, dtype=np.float64)
    assert got.shape == want.shape
    assert np.array_equal(np.isnan(got), np.isnan(want))
    return float(np.max(np.abs(got - want), initial=0.0, where=~np.isnan(want)))  # NaN where both are


def angle_diff(got: float, want: float) -> float:
    """|got - want| wrapped to [0, pi]: phi = pi and phi = -pi + 1e-17 are neighbours."""
    return abs(math.remainder(got - want, math.tau))


def quat_diff(got, want) -> float:
    """Max abs difference of two quaternions (4,), blind to the q / -q sign."""
    return min(max_diff(got, want), max_diff(-np.asarray(got), want))


def pose_diff(got, want: CameraPose) -> float:
    position, rotation, fov_deg = got
    assert fov_deg == want.vertical_fov_deg
    return max(max_diff(position, want.position_world), quat_diff(rotation, want.rotation_xyzw))


# --- the per-frame calls of both sides ------------------------------------------------------------


@dataclass
class Frame:
    """What one frame's FRAMING and MOTION answer (either side's, as plain values)."""

    a_world: np.ndarray
    b_world: np.ndarray
    b_is_gaze_point: bool
    has_torus: bool
    theta: float
    phi: float
    position_world: np.ndarray | None
    rotation_xyzw: np.ndarray | None
    framing_error: float
    flags: list[str] = field(default_factory=list)


def python_frame(framing: Framing, motion: ToricMotion, aims: list[np.ndarray], dt_s: float, last: CameraPose | None) -> Frame:
    """Framing.run and ToricMotion.run as the TORIC rig runs them (rig.py), and the framing error
    of the frame's pose (the last pose when the torus is degenerate, as the rig holds it)."""
    state, toric_frame = FrameState(frame=0, time_s=0.0, dt_s=dt_s, aim_points_world=aims), ToricFrame()
    framing.run(state, toric_frame)
    motion.run(state, toric_frame)
    pose = state.pose or last
    assert toric_frame.a_world is not None and toric_frame.b_world is not None
    return Frame(
        toric_frame.a_world,
        toric_frame.b_world,
        toric_frame.b_is_gaze_point,
        toric_frame.torus is not None,
        toric_frame.theta,
        toric_frame.phi,
        None if state.pose is None else state.pose.position_world,
        None if state.pose is None else state.pose.rotation_xyzw,
        math.nan if pose is None else framing.error(pose, toric_frame),
        state.flags,
    )


def native_frame(framing, motion, aims: list[np.ndarray], dt_s: float, last: tuple | None) -> Frame:
    a, b, gaze, torus, flags = framing.run(aims, dt_s)
    theta, phi, pose, motion_flags = motion.run(torus, gaze, dt_s)
    shown = pose or last
    error = math.nan if shown is None else framing.error(shown[0], shown[1], a, b, gaze)
    return Frame(
        a,
        b,
        gaze,
        torus is not None,
        theta,
        phi,
        None if pose is None else pose[0],
        None if pose is None else pose[1],
        error,
        flags + motion_flags,
    )


def frame_diff(got: Frame, want: Frame) -> float:
    """The largest difference of two frames (metres, radians, quaternion units, screen units);
    asserts that what must be identical is."""
    assert got.flags == want.flags
    assert (got.b_is_gaze_point, got.has_torus) == (want.b_is_gaze_point, want.has_torus)
    assert (got.position_world is None) == (want.position_world is None)
    diffs = [max_diff(got.a_world, want.a_world), max_diff(got.b_world, want.b_world)]
    diffs += [abs(got.theta - want.theta), angle_diff(got.phi, want.phi), max_diff(got.framing_error, want.framing_error)]
    if want.position_world is not None:
        diffs += [max_diff(got.position_world, want.position_world), quat_diff(got.rotation_xyzw, want.rotation_xyzw)]
    return max(diffs)


def state_diff(framing_core, motion_core, framing: Framing, motion: ToricMotion) -> float:
    """The largest difference of the state the two sides keep between frames; asserts the
    discrete state (the upright side, what has been set) identical."""
    assert motion_core.side == motion.side
    assert (motion_core.theta is None) == (motion.theta is None)
    assert (framing_core.last_aim is None) == (framing._last_aim is None)
    diffs = [angle_diff(framing_core.heading_rad, framing.heading_rad), abs(framing_core.alpha - framing.alpha)]
    diffs += [angle_diff(motion_core.phi, motion.phi), max_diff(motion_core.rate, motion.rate)]
    if motion.theta is not None:
        diffs.append(abs(motion_core.theta - motion.theta))
    if motion.position_world is not None:
        diffs.append(max_diff(motion_core.position_world, motion.position_world))
    if framing._last_aim is not None:
        diffs.append(max_diff(framing_core.last_aim, framing._last_aim))
    return max(diffs)


def pair(
    lens: Lens,
    style: Style,
    rotation: np.ndarray,
    framing_settings: FramingSettings | None = None,
    motion_settings: MotionSettings | None = None,
):
    """(Python Framing, Python ToricMotion, FramingCore, MotionCore), all made alike; settings None:
    each side's defaults."""
    framing_args = () if framing_settings is None else (framing_settings,)
    motion_args = () if motion_settings is None else (motion_settings,)
    return (
        Framing(lens, style, rotation, *framing_args),
        ToricMotion(style, lens, *motion_args),
        native.FramingCore(lens, style, rotation, *framing_args),
        native.MotionCore(style, lens, *motion_args),
    )


# --- per method -----------------------------------------------------------------------------------


@FAST
@given(lens=lenses, style=styles(), rotation=quaternion)
def test_framing_core_starts_like_framing(lens, style, rotation):
    framing, _, core, _ = pair(lens, style, rotation)
    assert angle_diff(core.heading_rad, framing.heading_rad) <= TOL
    assert abs(core.alpha - framing.alpha) <= TOL
    assert core.last_aim is None


def test_framing_core_heading_of_a_target_facing_up_is_zero():
    """A target whose +Z points straight up has no horizontal facing: heading 0, as in Python."""
    up = np.array([-math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)])  # -90 deg about x: +Z to +Y
    framing, _, core, _ = pair(Lens(), Style(), up)
    assert core.heading_rad == framing.heading_rad == 0.0


@FAST
@given(
    lens=lenses, style=styles(), rotation=quaternion, start=point, steps=st.lists(st.tuples(offset, dts), min_size=1, max_size=4)
)
def test_framing_core_one_target_gaze_point_and_heading(lens, style, rotation, start, steps):
    """One target over a few frames: A, the gaze-room point B, the torus and the heading."""
    framing, motion, core, motion_core = pair(lens, style, rotation)
    aim = start
    for move, dt_s in steps:
        aim = aim + move
        got = native_frame(core, motion_core, [aim], dt_s, None)
        want = python_frame(framing, motion, [aim], dt_s, None)
        assert frame_diff(got, want) <= TOL
        assert state_diff(core, motion_core, framing, motion) <= TOL


@FAST
@given(
    lens=lenses,
    style=styles(),
    a=point,
    b_offset=st.one_of(ab_offset, offset.map(lambda o: o * 1e-4), st.just(np.zeros(3))),
    dt_s=dts,
)
def test_framing_core_two_targets(lens, style, a, b_offset, dt_s):
    """Two targets, apart, within min_ab_distance_m (framed as one) or at the same point."""
    framing, motion, core, motion_core = pair(lens, style, np.array([0.0, 0.0, 0.0, 1.0]))
    aims = [a, a + b_offset]
    got, want = native_frame(core, motion_core, aims, dt_s, None), python_frame(framing, motion, aims, dt_s, None)
    assert frame_diff(got, want) <= TOL


def test_framing_core_flags_a_degenerate_torus():
    """Targets closer than make_torus allows but farther than min_ab_distance_m: no torus, the
    pose held (FRAMING's "degenerate_torus", MOTION's "pose_held")."""
    framing, motion, core, motion_core = pair(
        Lens(), Style(), np.array([0.0, 0.0, 0.0, 1.0]), FramingSettings(min_ab_distance_m=1e-9)
    )
    aims = [np.array([1.0, 2.0, 3.0]), np.array([1.0, 2.0, 3.0 + 1e-8])]
    got, want = native_frame(core, motion_core, aims, 0.0, None), python_frame(framing, motion, aims, 0.0, None)
    assert got.flags == want.flags == ["degenerate_torus", "pose_held"]
    assert frame_diff(got, want) == 0.0


@FAST
@given(lens=lenses, style=styles(), a=point, b_offset=offset, position=point, rotation=quaternion, gaze=st.booleans())
def test_framing_core_error(lens, style, a, b_offset, position, rotation, gaze):
    """The framing error from any pose, NaN when a framed point is behind the camera."""
    b = a + b_offset
    framing, _, core, _ = pair(lens, style, rotation)
    toric_frame = ToricFrame(a_world=a, b_world=b, b_is_gaze_point=gaze)
    want = framing.error(CameraPose(position, rotation, lens.vertical_fov_deg), toric_frame)
    assert max_diff(core.error(position, rotation, a, b, gaze), want) <= TOL


@FAST
@given(lens=lenses, style=styles(), a=point, b_offset=offset)
def test_framing_core_error_of_the_composed_pose_is_zero(lens, style, a, b_offset):
    """From the pose MOTION composes for two targets, both land on their screen points."""
    assume(np.linalg.norm(b_offset) > 0.1)
    framing, motion, core, motion_core = pair(lens, style, np.array([0.0, 0.0, 0.0, 1.0]))
    got = native_frame(core, motion_core, [a, a + b_offset], 0.0, None)
    assume(got.has_torus)
    assert got.framing_error <= 1e-6


@st.composite
def tori(draw):
    """(lens, style, torus): the torus of two targets at the style's composition angle."""
    lens, style, a, b_offset = draw(lenses), draw(styles()), draw(point), draw(ab_offset)
    assume(np.linalg.norm(b_offset) > 0.05)
    alpha = toric.composition_angle(style.screen_a, style.screen_b, lens)
    assume(toric.MIN_ALPHA_RAD <= alpha <= math.pi - toric.MIN_ALPHA_RAD)
    return lens, style, a, a + b_offset, alpha


@FAST
@given(case=tori())
def test_motion_core_preferred_place(case):
    lens, style, a, b, alpha = case
    motion, core = ToricMotion(style, lens), native.MotionCore(style, lens)
    got, want = core.preferred_place(native.make_torus(a, b, alpha)), motion.preferred_place(toric.make_torus(a, b, alpha))
    assert max(abs(g - w) for g, w in zip(got, want)) <= TOL
    assert core.side == motion.side


@FAST
@given(case=tori(), fraction=st.floats(0.01, 0.99), phi=st.floats(-math.pi, math.pi), level=st.booleans())
def test_pose_on_torus(case, fraction, phi, level):
    lens, style, a, b, alpha = case
    theta = fraction * toric.theta_max(alpha)
    try:
        want = pose_on_torus(toric.make_torus(a, b, alpha), theta, phi, style, lens, level)
    except ValueError:  # the camera in line with A and B: the native one refuses too
        with pytest.raises(ValueError):
            native.pose_on_torus(native.make_torus(a, b, alpha), theta, phi, style, lens, level)
        return
    assert pose_diff(native.pose_on_torus(native.make_torus(a, b, alpha), theta, phi, style, lens, level), want) <= TOL


@FAST
@given(
    case=tori(),
    moves=st.lists(st.tuples(offset, offset.map(lambda o: o * 0.2), dts), min_size=1, max_size=4),
    level=st.booleans(),
)
def test_motion_core_run(case, moves, level):
    """A few frames on moving tori: the place, the pose and the rates the spring leaves."""
    lens, style, a, b, alpha = case
    motion, core = ToricMotion(style, lens), native.MotionCore(style, lens)
    for move_a, move_b, dt_s in moves:
        a, b = a + move_a, b + move_b
        assume(np.linalg.norm(b - a) > 0.05)
        assume(math.hypot(b[0] - a[0], b[2] - a[2]) > 0.05)  # A straight above B: the side is a tie (module docstring)
        state, toric_frame = FrameState(frame=0, time_s=0.0, dt_s=dt_s), ToricFrame(b_is_gaze_point=level)
        toric_frame.torus = toric.make_torus(a, b, alpha)
        motion.run(state, toric_frame)
        theta, phi, pose, flags = core.run(native.make_torus(a, b, alpha), level, dt_s)
        assert state.pose is not None and flags == state.flags == []
        assert max(abs(theta - toric_frame.theta), angle_diff(phi, toric_frame.phi), pose_diff(pose, state.pose)) <= TOL
        assert max_diff(core.rate, motion.rate) <= TOL and core.side == motion.side


@FAST
@given(lens=lenses, first=styles(), second=styles(), a=point, b_offset=ab_offset, dt_s=st.floats(0.001, 0.1))
def test_set_style(lens, first, second, a, b_offset, dt_s):
    """A style changed between frames: the next frame frames and moves by the new one."""
    framing, motion, core, motion_core = pair(lens, first, np.array([0.0, 0.0, 0.0, 1.0]))
    for style in (first, second):
        framing.set_style(style)
        motion.set_style(style)
        core.set_style(style)
        motion_core.set_style(style)
        for aims in ([a], [a, a + b_offset]):
            got, want = native_frame(core, motion_core, aims, dt_s, None), python_frame(framing, motion, aims, dt_s, None)
            assert frame_diff(got, want) <= TOL
    assert state_diff(core, motion_core, framing, motion) <= TOL


@FAST
@given(
    lens=lenses,
    style=styles(),
    a=point,
    height=st.one_of(st.floats(0.05, 8.0), st.floats(-8.0, -0.05)),
    moves=st.lists(st.tuples(st.floats(-0.3, 0.3), dts), min_size=1, max_size=4),
    level=st.booleans(),
)
def test_motion_core_breaks_the_side_tie_of_b_straight_above_a_as_the_python(lens, style, a, height, moves, level):
    """B straight above or below A: the torus is symmetric about world up, both halves equally
    upright up to rounding, and both sides take +1 (MotionSettings.side_tie); then every frame,
    B moving straight up and down, agrees."""
    alpha = toric.composition_angle(style.screen_a, style.screen_b, lens)
    assume(toric.MIN_ALPHA_RAD <= alpha <= math.pi - toric.MIN_ALPHA_RAD)
    motion, core = ToricMotion(style, lens), native.MotionCore(style, lens)
    for rise, dt_s in moves:
        b = a + np.array([0.0, height + rise, 0.0])
        state, toric_frame = FrameState(frame=0, time_s=0.0, dt_s=dt_s), ToricFrame(b_is_gaze_point=level)
        toric_frame.torus = toric.make_torus(a, b, alpha)
        motion.run(state, toric_frame)
        theta, phi, pose, flags = core.run(native.make_torus(a, b, alpha), level, dt_s)
        assert core.side == motion.side == 1.0
        assert state.pose is not None and flags == state.flags == []
        assert max(abs(theta - toric_frame.theta), angle_diff(phi, toric_frame.phi), pose_diff(pose, state.pose)) <= TOL


def test_motion_core_breaks_the_side_tie_of_mirror_images_as_the_python():
    """The tie of the drawn styles' exclusions: screen points one above the other, the halves
    mirror images. Rounding chooses nothing (with MotionSettings.side_tie 0 the compiled side takes
    -1 for the second B, the Python +1)."""
    lens, style = Lens(), Style(screen_a=(0.1, -0.3), screen_b=(0.1, 0.3))
    a = np.array([1.0, 0.5, -2.0])
    for b in (a + [3.0, 0.0, 1.0], a + [0.0, 2.0, 0.0], a + [0.5, -1.0, 2.0]):
        alpha = toric.composition_angle(style.screen_a, style.screen_b, lens)
        motion, core = ToricMotion(style, lens), native.MotionCore(style, lens)
        want, got = motion.preferred_place(toric.make_torus(a, b, alpha)), core.preferred_place(native.make_torus(a, b, alpha))
        assert core.side == motion.side == 1.0 and max(abs(g - w) for g, w in zip(got, want)) <= TOL


def test_the_cores_state_is_set_as_it_is_read():
    """What a rig copies between the Python stages and the cores (compiled_rig.py), back as given."""
    framing, motion = native.FramingCore(Lens(), Style(), np.array([0.0, 0.0, 0.0, 1.0])), native.MotionCore(Style(), Lens())
    framing.heading_rad, framing.last_aim = 0.25, np.array([1.0, 2.0, 3.0])
    assert framing.heading_rad == 0.25 and framing.last_aim.tolist() == [1.0, 2.0, 3.0]
    framing.last_aim = None
    assert framing.last_aim is None
    motion.theta, motion.phi, motion.rate, motion.position_world = 0.5, -1.0, np.array([0.1, 0.2]), (4.0, 5.0, 6.0)
    motion.side, motion.side_key = -1.0, 0.3
    assert (motion.theta, motion.phi, motion.rate.tolist()) == (0.5, -1.0, [0.1, 0.2])
    assert motion.position_world.tolist() == [4.0, 5.0, 6.0]
    assert (motion.side, motion.side_key) == (-1.0, 0.3)
    motion.theta, motion.position_world, motion.side_key = None, None, None
    assert (motion.theta, motion.position_world, motion.side_key) == (None, None, None)
    with pytest.raises(ValueError, match="rate must have shape"):
        motion.rate = np.zeros(3)


def test_motion_core_holds_its_place_without_a_torus():
    motion, core = ToricMotion(Style(), Lens()), native.MotionCore(Style(), Lens())
    state, toric_frame = FrameState(frame=0, time_s=0.0, dt_s=0.1), ToricFrame()
    motion.run(state, toric_frame)
    assert (
        core.run(None, False, 0.1) == (toric_frame.theta, toric_frame.phi, None, state.flags) == (0.0, 0.0, None, ["pose_held"])
    )


# --- long sequences -------------------------------------------------------------------------------

FRAMES = 2400
SECOND_STYLE = Style(
    screen_a=(-0.2, 0.15),
    screen_b=(0.4, -0.1),
    gaze_room_m=1.5,
    preferred_theta_ratio=0.6,
    preferred_phi_deg=35.0,
    response_time_s=0.3,
    max_speed_m_s=4.0,
    max_accel_m_s2=6.0,
)


def scene_frames(targets: int, seed: int) -> list[tuple[list[np.ndarray], float]]:
    """FRAMES frames (aim points, dt_s) of the demo scene's walker (60 s of walking, then it
    stands: the target stops), alone or with a second target circling it at a varying radius and
    height. The frame gaps are random around 1/60 s, with repeated frames (dt 0), long gaps that
    the motion's substeps cannot cover, and pauses; the walker jumps now and then; with two
    targets, the second passes straight above the first, and coincides with it for a few frames
    (exactly, within min_ab_distance_m, and closer than make_torus allows)."""
    rng = np.random.default_rng(seed)
    scene = build_demo_scene(seed=seed, duration_s=60.0)
    frames, time_s, jump = [], 0.0, np.zeros(3)
    for i in range(FRAMES):
        kind = rng.random()
        dt_s = 0.0 if kind < 0.03 else float(rng.uniform(0.3, 1.2)) if kind < 0.05 else float(rng.uniform(0.008, 0.03))
        dt_s = 0.0 if i == 0 else dt_s
        time_s += dt_s
        if rng.random() < 0.01:
            jump = jump + rng.normal(size=3) * [2.0, 0.3, 2.0]
        a = scene.aim_point_world(time_s) + jump
        if targets == 1:
            frames.append(([a], dt_s))
            continue
        angle, radius_m = 0.7 * time_s, 3.0 + 2.0 * math.sin(0.13 * time_s)
        b = a + np.array([radius_m * math.cos(angle), 0.8 * math.sin(0.31 * time_s), radius_m * math.sin(angle)])
        if 600 <= i < 620:
            b = a + np.array([0.0, 2.5, 0.0])  # straight above: the torus's fallback reference
        elif 1400 <= i < 1403:
            b = a.copy()
        elif 1403 <= i < 1406:
            b = a + np.array([4e-4, 0.0, -3e-4])
        elif 1406 <= i < 1409:
            b = a + np.array([0.0, 3e-7, 0.0])  # below make_torus's 1e-6 m
        frames.append(([a, b], dt_s))
    return frames


def run_both(
    frames, lens: Lens, framing_settings: FramingSettings | None = None, motion_settings: MotionSettings | None = None
) -> tuple[float, float, list[Frame]]:
    """Drives both sides through the frames, the style changed half-way; answers the largest frame
    and state differences and the native frames."""
    rotation = build_demo_scene(seed=7, duration_s=20.0).avatar.transform.rotation_xyzw
    framing, motion, core, motion_core = pair(lens, Style(), rotation, framing_settings, motion_settings)
    worst_frame = worst_state = 0.0
    last_py: CameraPose | None = None
    last_native: tuple | None = None
    got_frames = []
    for i, (aims, dt_s) in enumerate(frames):
        if i == len(frames) // 2:
            for stage in (framing, motion, core, motion_core):
                stage.set_style(SECOND_STYLE)
        got = native_frame(core, motion_core, aims, dt_s, last_native)
        want = python_frame(framing, motion, aims, dt_s, last_py)
        worst_frame = max(worst_frame, frame_diff(got, want))
        worst_state = max(worst_state, state_diff(core, motion_core, framing, motion))
        if want.position_world is not None and want.rotation_xyzw is not None:  # so is got's (frame_diff)
            last_native = (got.position_world, got.rotation_xyzw)
            last_py = CameraPose(want.position_world, want.rotation_xyzw, lens.vertical_fov_deg)
        got_frames.append(got)
    return worst_frame, worst_state, got_frames


COARSE_MOTION = MotionSettings(
    max_substep_s=0.05, max_substeps=3, theta_margin_rad=0.1, side_hysteresis=0.05, side_recheck_axis_dot=0.1
)
LONG_CASES = {  # name: (targets, seed, lens, framing settings, motion settings)
    "one_target": (1, 11, Lens(), None, None),
    "two_targets": (2, 12, Lens(vertical_fov_deg=65.0, aspect=1.5), None, None),
    # min_ab_distance_m below make_torus's 1e-6 m: the coinciding targets give degenerate tori
    "two_targets_degenerate": (2, 13, Lens(), FramingSettings(min_ab_distance_m=1e-9), None),
    "two_targets_other_settings": (
        2,
        14,
        Lens(),
        FramingSettings(heading_time_constant_s=0.2, heading_min_speed_m_s=0.5, min_ab_distance_m=0.01),
        COARSE_MOTION,
    ),
}


@pytest.mark.parametrize("case", sorted(LONG_CASES))
def test_long_sequence_agrees_every_frame(case):
    targets, seed, lens, framing_settings, motion_settings = LONG_CASES[case]
    frames = scene_frames(targets, seed)
    worst_frame, worst_state, got = run_both(frames, lens, framing_settings, motion_settings)
    print(f"{case}: largest frame difference {worst_frame:.3g}, state {worst_state:.3g}")
    assert worst_frame <= TOL and worst_state <= TOL
    flags = {flag for frame in got for flag in frame.flags}
    expected = {"one_target": set(), "two_targets": {"targets_coincide"}, "two_targets_other_settings": {"targets_coincide"}}
    assert flags == expected.get(case, {"targets_coincide", "degenerate_torus", "pose_held"})


def test_long_sequence_repeats_bit_for_bit():
    frames = scene_frames(2, 12)
    _, _, first = run_both(frames, Lens())
    _, _, second = run_both(frames, Lens())
    for got, again in zip(first, second, strict=True):
        assert got.flags == again.flags and (got.theta, got.phi) == (again.theta, again.phi)
        assert got.position_world is not None and again.position_world is not None
        assert np.array_equal(got.position_world, again.position_world) and np.array_equal(got.rotation_xyzw, again.rotation_xyzw)
        assert np.array_equal(got.b_world, again.b_world) and got.framing_error == again.framing_error
