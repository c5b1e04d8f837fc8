"""The rig contract: what the camera rig of a session does, and the one choice of rig.

A rig runs the stages after INGEST (pipeline/stages.py) for one session, for the session's whole
life. Three rigs implement `CameraRig`, structurally (each says so in its docstring): TORIC
(pipeline/toric/rig.py), TRACKS (pipeline/tracks/rig.py) and MATCH (pipeline/match/rig.py);
`make_rig` (pipeline/rigs.py) chooses among them, there and nowhere else, so that this contract
knows none of its implementations.

Every rig runs a frame, takes a style and is closed. What only some rigs do is part of the
contract too, declared as such, and every rig answers it:
- work left for later: `has_deferred_work` and `do_deferred_work` (TORIC's amortized map update,
  MATCH's drawn plan); a rig that never defers has none;
- a question has a "none" answer, which a rig without the capability always gives:
  `anticipation_map` (TORIC in a map mode) and `program_transforms` (MATCH) answer None;
- a rig bound to its thread says so (`thread_bound`: TORIC's GL maps);
- an input only some rigs take is a capability object, None on a rig that takes no such input:
  `player_inputs` (MATCH: a frame's game events and a human director's takes, both naming its
  players), so that the session table refuses such an input before it writes it anywhere.
`RigBase` gives a rig those answers of a rig without the capability (Cinemachine's component base),
so that a rig overrides what it does and says nothing about the rest.
Code outside a rig's folder asks this contract, never which rig it holds (tests/test_layout.py);
tests/pipeline/test_rig_contract.py holds every rig to it.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
import numpy.typing as npt

from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.inputs import FrameInput
from camdirector.pipeline.match.frame import ShotChoice, ShotKind
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.style import Style


class PlayerInputs(Protocol):
    """What a rig that directs among a game's players takes besides their transforms (MATCH):
    a frame's game events (`FrameInput.events`) and a human director's takes, both naming players."""

    player_ids: frozenset[str]  # whom a game event or a take may name

    def take(self, subject_ids: list[str], kind: ShotKind | None, release: bool) -> ShotChoice | None:
        """Holds a human's shot of `subject_ids` from the next frame until released, and returns
        it; None on `release`, which gives the program back to the director. kind None: the kind
        that fits the number of subjects. Raises ValueError for a take that cannot be held (an
        unknown or repeated player, a kind that does not fit the number)."""
        ...


# An A-map as a rig answers it: (n, n) A in [0, 1], rows theta and columns phi, and the texel (i, j)
# of the camera (`CameraRig.anticipation_map`).
AnticipationView = tuple[npt.NDArray[np.float32], tuple[float, float]]


class CameraRig(Protocol):
    """The camera rig of one session (module docstring)."""

    # -- What every rig does ------------------------------------------------------------------

    def run(
        self, state: FrameState, update: FrameInput, target_transforms: list[RigidTransform], last: FrameState | None
    ) -> None:
        """The stages after INGEST: sets the rig's part of `state` (pipeline/state.py) and fills
        it and the core, timed into `state.stage_ms`. target_transforms: the targets' as of
        `update`, in target order; last: the session's last answered state (None before the first)."""
        ...

    def set_style(self, style: Style) -> None:
        """From the next frame on (each rig says what a change does: a cut, another director)."""
        ...

    def close(self) -> None:
        """Releases what the rig holds outside Python's memory (the occlusion maps' GL objects or
        Embree scenes); idempotent. The rig runs no frame afterwards."""
        ...

    # -- What only some rigs do: every rig answers, a rig without it as written here ---------

    @property
    def has_deferred_work(self) -> bool:
        """Whether the rig left work for later that a later frame does if nobody did it before
        (TORIC's amortized map update, MATCH's drawn plan); False on a rig that never defers."""
        ...

    def do_deferred_work(self, whole: bool = True) -> bool:
        """Does the deferred work now, or without `whole` a part of it (a worker's idle moment, a
        snapshot); answers whether there was any (never, on a rig that never defers). What the rig
        answers never depends on whether, when or in how many parts this ran."""
        ...

    def anticipation_map(self, state: FrameState | None) -> AnticipationView | None:
        """TORIC in a map mode: the occlusion anticipation map (n, n) float, A in [0, 1], rows
        theta and columns phi, and the texel (i, j) of the camera of `state` (the last answered
        frame). None: no A-map (a rig without occlusion maps, a TORIC style that is not a map
        mode, or no maps computed yet)."""
        ...

    @property
    def program_transforms(self) -> list[RigidTransform] | None:
        """MATCH: the targets at the program's moment, which the broadcast delay puts behind the
        game (what the camera shows). None: the camera shows the targets as of the latest frame
        (every other rig, and MATCH while its delay fills)."""
        ...

    @property
    def player_inputs(self) -> PlayerInputs | None:
        """MATCH: game events and a human's takes (`PlayerInputs`). None: the rig takes neither;
        a frame with events and a TakeShot are refused."""
        ...

    @property
    def thread_bound(self) -> bool:
        """TORIC with GL occlusion maps: the rig holds objects of an EGL context, which is current
        on the thread that made it, so its frames must run on that thread (a front that holds
        sessions answers them on its loop's thread, not the edge's). False: any thread will do."""
        ...


class RigBase:
    """What a rig answers of what only some rigs do when it does none of it (the "as written" of
    `CameraRig`): no deferred work, no A-map, the targets as of the latest frame, no player
    inputs. A rig inherits it and overrides what it does; it is no part of the contract, which
    stays the `CameraRig` Protocol."""

    program_transforms: list[RigidTransform] | None = None  # CameraRig: no delayed program

    @property
    def has_deferred_work(self) -> bool:
        """CameraRig: False, the rig never leaves work for later."""
        return False

    def do_deferred_work(self, whole: bool = True) -> bool:
        """CameraRig: there is never any."""
        return False

    def anticipation_map(self, state: FrameState | None) -> AnticipationView | None:
        """CameraRig: None, the rig draws no A-map."""
        return None

    @property
    def player_inputs(self) -> PlayerInputs | None:
        """CameraRig: None, the rig takes no game events and no takes."""
        return None

    @property
    def thread_bound(self) -> bool:
        """CameraRig: False, the rig holds nothing bound to a thread."""
        return False
