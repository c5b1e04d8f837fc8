"""Random sample points on the targets' surfaces, the points the visibility maps are computed from.

Paper: occlusion-anticipation-toric-space.md, section 4.1 ("r random sample points on the surface of
each target object", after [CNO12]) and section 6 (Table 3: "at each update, we recompute the maps
for one sample on each target"). The paper does not say when a point is drawn; we draw a fresh
point for a slot each time its map is recomputed, so that over a few updates the samples sweep the
whole surface instead of watching the same r points for the whole session, and the 2r maps of the
A-map are always r independent draws per target.

Points are uniform over each mesh's area, drawn in the target's local frame and carried by its
current transform. Slots are numbered slot = target * r + sample, as in pipeline/toric/anticipation_map.py.
(pipeline/toric/visibility.py keeps its own fixed per-session points for the rig's visibility estimate.)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from camdirector.geometry.meshes import TriMesh
from camdirector.geometry.transforms import RigidTransform


class SurfaceSampler:
    """Uniform points on one mesh's surface: the area table is built once, a draw is O(log faces)."""

    def __init__(self, mesh: TriMesh) -> None:
        tri = mesh.vertices[mesh.faces]  # (m, 3, 3)
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        total = float(area.sum())
        if not total > 0.0:
            raise ValueError("SurfaceSampler: the mesh has no area")
        self._corner = tri[:, 0]
        self._edge1 = tri[:, 1] - tri[:, 0]
        self._edge2 = tri[:, 2] - tri[:, 0]
        self._cdf = np.cumsum(area) / total
        self.area_m2 = total
        self._mesh = mesh

    def __reduce__(self) -> tuple[type[SurfaceSampler], tuple[TriMesh]]:
        """Pickled as its mesh (a session's checkpoint names the mesh instead of copying it): the
        tables are a function of the mesh alone."""
        return SurfaceSampler, (self._mesh,)

    def sample(self, count: int, rng: np.random.Generator) -> npt.NDArray[np.float64]:
        """(count, 3) float64 points, local frame, uniform over the area."""
        face = np.minimum(np.searchsorted(self._cdf, rng.random(count), side="right"), len(self._cdf) - 1)
        u, v = rng.random(count), rng.random(count)
        fold = u + v > 1.0  # reflect the unit square's upper half onto the triangle
        u[fold], v[fold] = 1.0 - u[fold], 1.0 - v[fold]
        points: npt.NDArray[np.float64] = self._corner[face] + u[:, None] * self._edge1[face] + v[:, None] * self._edge2[face]
        return points

    def point_at(self, face_draw: float, u: float, v: float) -> npt.NDArray[np.float64]:
        """(3,) float64, local frame: what sample(1, rng) makes of the draws face_draw, u, v in
        [0, 1), the same bits, in scalars (a map update's one point a slot: numpy's arrays of one
        cost it 31 µs for two slots against 8)."""
        face = min(int(np.searchsorted(self._cdf, face_draw, side="right")), len(self._cdf) - 1)
        if u + v > 1.0:
            u, v = 1.0 - u, 1.0 - v
        point: npt.NDArray[np.float64] = self._corner[face] + u * self._edge1[face] + v * self._edge2[face]
        return point


@dataclass(frozen=True)
class TargetSamplingSettings:
    samples_per_target: int = 5  # r (the paper's Table 2); keep equal to AnticipationSettings.samples_per_target. [1, 64]

    def __post_init__(self) -> None:
        if not 1 <= self.samples_per_target <= 64:
            raise ValueError("TargetSamplingSettings: samples_per_target must be in [1, 64]")


class TargetSampler:
    """r sample points per target (one or two targets), each re-drawn when its map is refreshed."""

    def __init__(
        self,
        target_meshes: Sequence[TriMesh],
        rng: np.random.Generator,
        settings: TargetSamplingSettings = TargetSamplingSettings(),
    ) -> None:
        if len(target_meshes) not in (1, 2):
            raise ValueError("TargetSampler: one or two target meshes")
        self.settings = settings
        self._samplers = [SurfaceSampler(m) for m in target_meshes]
        r = settings.samples_per_target
        self.points_local = np.concatenate([s.sample(r, rng) for s in self._samplers])  # (slots, 3)

    @property
    def target_count(self) -> int:
        return len(self._samplers)

    @property
    def slot_count(self) -> int:
        return self.target_count * self.settings.samples_per_target

    def target_of(self, slot: int) -> int:
        """Index of the target a slot's point lies on."""
        if not 0 <= slot < self.slot_count:
            raise ValueError(f"slot {slot} outside [0, {self.slot_count})")
        return slot // self.settings.samples_per_target

    def redraw(self, slots: Sequence[int], rng: np.random.Generator) -> None:
        """Fresh uniform points for these slots (the others keep theirs): each slot's point is
        SurfaceSampler.sample(1, rng)'s, the slots in order, from one draw of the generator."""
        draws = rng.random((len(slots), 3))  # per slot: face, u, v, as sample(1) draws them one by one
        for slot, (face_draw, u, v) in zip(slots, draws.tolist()):
            self.points_local[slot] = self._samplers[self.target_of(int(slot))].point_at(face_draw, u, v)

    def points_world(
        self, target_transforms: Sequence[RigidTransform], slots: Sequence[int] | None = None
    ) -> npt.NDArray[np.float64]:
        """(len(slots), 3) world metres: the slots' points (all slots if None) under the targets' transforms."""
        if len(target_transforms) != self.target_count:
            raise ValueError("points_world: one transform per target")
        chosen = range(self.slot_count) if slots is None else [int(s) for s in slots]
        out = np.empty((len(chosen), 3))
        for row, slot in enumerate(chosen):
            out[row] = target_transforms[self.target_of(slot)].apply(self.points_local[slot][None, :])[0]
        return out
