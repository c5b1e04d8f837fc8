"""A scenario's generated objects: a scatter of static items (a forest) and spawned movers (the
stress test), deterministic from their seed.

What a generator may say is in evaluation/scenario_schema.py ("Generators"). A scatter places
each item at random in its region, at min_spacing_m from the others, out of the excluded regions,
and with its footprint (its first part, e.g. the trunk under a crown) clear_of_targets_m from
every target's path centre line; a spawn starts its objects in batches spread evenly over
[start_s, end_s], each clear_of_targets_m from the targets at that moment, on a straight line in a
random horizontal direction bouncing off the region's sides (scenario_motion.BounceMotion).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from camdirector.evaluation.scenario import Actor, Shape
from camdirector.evaluation.scenario_motion import BounceMotion, yaw_quat
from camdirector.evaluation.scenario_schema import RegionSpec, ScatterSpec, SpawnSpec
from camdirector.geometry.transforms import IDENTITY_QUAT

_PATH_SAMPLE_HZ = 20.0  # how densely target paths are sampled for generator clearances
_MAX_PLACEMENT_TRIES = 200  # per generated item, before the generator gives up

Region = tuple[tuple[float, float], tuple[float, float]]  # (x min, x max), (z min, z max), m


class PlacementError(ValueError):
    """A generator that cannot place its items; `key`: the generator's key at fault, if one is."""

    def __init__(self, problem: str, key: str | None = None):
        super().__init__(problem)
        self.key = key


def _region(spec: RegionSpec) -> Region:
    return (spec.x[0], spec.x[1]), (spec.z[0], spec.z[1])


def _in_region(xz: np.ndarray, region: Region) -> bool:
    (x0, x1), (z0, z1) = region
    return bool(x0 <= xz[0] <= x1 and z0 <= xz[1] <= z1)


def _target_paths_xz(targets: list[Actor], duration_s: float) -> cKDTree | None:
    if not targets:
        return None
    times = np.linspace(0.0, duration_s, max(2, int(duration_s * _PATH_SAMPLE_HZ) + 1))
    return cKDTree(np.concatenate([a.transforms_at(times)[0][:, [0, 2]] for a in targets]))


def scatter(
    spec: ScatterSpec, parts: list[tuple[Shape, np.ndarray]], seed: int, targets: list[Actor], duration_s: float
) -> list[Actor]:
    """The scatter's static items, each of `parts` (its shape, and the offset from the item's ground
    point to the part's lowest point). Raises PlacementError."""
    count, prefix = spec.count, spec.id_prefix
    region = _region(spec.region)
    scale_lo, scale_hi = spec.scale
    spacing, clearance = spec.min_spacing_m, spec.clear_of_targets_m
    excluded = [_region(r) for r in spec.exclude]
    rng = np.random.default_rng(seed)
    paths = _target_paths_xz(targets, duration_s) if clearance > 0.0 else None
    footprint, offset = parts[0]  # the first part stands on the ground (a trunk under its crown)
    reach = footprint.horizontal_radius + float(np.hypot(offset[0], offset[2]))  # at scale 1, m
    placed: list[np.ndarray] = []
    out: list[Actor] = []
    tries = 0
    while len(placed) < count:
        tries += 1
        if tries > _MAX_PLACEMENT_TRIES * count:
            raise PlacementError(
                f"placed only {len(placed)} of {count} items; lower count, "
                "min_spacing_m or clear_of_targets_m, or widen the region"
            )
        xz = np.array([rng.uniform(*region[0]), rng.uniform(*region[1])])
        scale = rng.uniform(scale_lo, scale_hi)
        yaw = rng.uniform(-math.pi, math.pi) if spec.random_yaw else 0.0
        if any(_in_region(xz, r) for r in excluded):
            continue
        if placed and np.min(np.linalg.norm(np.array(placed) - xz, axis=1)) < spacing:
            continue
        if paths is not None and paths.query(xz)[0] < clearance + reach * scale:
            continue
        placed.append(xz)
        rot = yaw_quat(yaw)
        r = Rotation.from_quat(rot)
        index = len(placed) - 1
        for j, (shape, part_offset) in enumerate(parts):
            local = part_offset * scale
            local[1] -= shape.lowest_y * scale  # offset is to the part's lowest point
            pos = np.array([xz[0], spec.ground_y, xz[1]]) + r.apply(local)
            part_id = f"{prefix}{index:03d}" + (f".{j}" if len(parts) > 1 else "")
            out.append(Actor(part_id, "object", shape, pos, rot.copy(), np.full(3, scale * shape.file_scale), dynamic=False))
    return out


def spawn(spec: SpawnSpec, shape: Shape, seed: int, targets: list[Actor]) -> list[Actor]:
    """The spawn's dynamic objects, parked until their spawn_s. Raises PlacementError."""
    count, batch, prefix = spec.count, spec.batch, spec.id_prefix
    start_s = spec.start_s
    end_s = start_s if spec.end_s is None else spec.end_s
    region = _region(spec.region)
    speed_lo, speed_hi = spec.speed_m_s
    clearance = spec.clear_of_targets_m
    rng = np.random.default_rng(seed)
    radius = shape.horizontal_radius
    x_range = (region[0][0] + radius, region[0][1] - radius)
    z_range = (region[1][0] + radius, region[1][1] - radius)
    if x_range[0] > x_range[1] or z_range[0] > z_range[1]:
        raise PlacementError("is narrower than the shape", "region")
    events = -(-count // batch)
    out = []
    for i in range(count):
        t = start_s + (end_s - start_s) * ((i // batch) / (events - 1) if events > 1 else 0.0)
        near = [a.transforms_at(np.array([t]))[0][0, [0, 2]] for a in targets]
        for _ in range(_MAX_PLACEMENT_TRIES):
            xz = np.array([rng.uniform(*x_range), rng.uniform(*z_range)])
            if all(np.linalg.norm(xz - p) >= clearance + radius for p in near):
                break
        else:
            raise PlacementError(
                f"cannot place {prefix}{i:03d} {clearance:g} m clear of the targets at "
                f"t = {t:g} s; lower clear_of_targets_m or widen the region"
            )
        heading = rng.uniform(-math.pi, math.pi)
        speed = rng.uniform(speed_lo, speed_hi)
        origin = np.array([xz[0], spec.ground_y - shape.lowest_y, xz[1]])
        velocity = speed * np.array([math.sin(heading), 0.0, math.cos(heading)])
        motion = BounceMotion(origin, velocity, t, x_range, z_range)
        out.append(
            Actor(
                f"{prefix}{i:03d}",
                "object",
                shape,
                origin,
                IDENTITY_QUAT.copy(),
                np.full(3, shape.file_scale),
                dynamic=True,
                motion=motion,
                spawn_s=t,
            )
        )
    return out
