"""The shared BVH clips the overview tests use, read from the `shared_data` fixture's folder
(tests/conftest.py: skipped with a reason where ../shared/data is absent, a failure under
CAMDIRECTOR_REQUIRE_SHARED_DATA=1). Clips are read in place and never copied."""

from __future__ import annotations

import functools
from pathlib import Path

from camdirector.precompute.overview.bvh import MotionClip, load_motion

# name -> (path under shared/data/mocap, leading frames to skip: T-pose or rest pose, SOURCES.md 2)
CLIPS = {
    "walk": ("bandai_namco/dataset-1_walk_normal_001.bvh", 0),
    "run": ("bandai_namco/dataset-1_run_active_001.bvh", 0),
    "kick": ("bandai_namco/dataset-1_kick_normal_001.bvh", 0),
    "punch": ("bandai_namco/dataset-1_punch_normal_001.bvh", 0),
    "dance": ("bandai_namco/dataset-1_dance-short_normal_001.bvh", 0),
    "cmu_01_01": ("cmu/01_01.bvh", 1),
    "perfume_a": ("perfume/A_test.bvh", 1),
}


@functools.cache
def load_clip(shared_data: Path, name: str) -> MotionClip:
    path, skip = CLIPS[name]
    return load_motion(shared_data / "mocap" / path, skip_frames=skip)
