"""Settings of the camera tracks' precompute: one typed object (the runtime director's are in
pipeline/tracks/settings.py).

Defaults are the paper's where it gives a value (Section 5.1: occlusion and framing violations
trigger a cut after 200 ms; Section 5.3: the 30-degree rule) and Recast's demo defaults for the
agent and the derived navigation mesh (agent height 2.0 m, radius 0.6 m, climb 0.9 m, slope 45
deg, regions under 8 x 8 cells of 0.3 m dropped). Every other value is our choice, documented on
its line and in the module that uses it. All lengths are metres (after the level's scale), angles
degrees where the name says `_deg`, times seconds.
"""
from __future__ import annotations

from dataclasses import dataclass

# The player a level is sized for where its command is not told (`camdirector level add`'s
# --agent-height and --agent-radius, `camdirector import-match --map`), m: a grown person, 1.75 m
# tall and 0.5 m in radius, which is QuakeWorld's player (56 x 32 units) at the scale its maps and
# demos are read in (geometry/quake_frame.py chose that scale so). One size for both commands: the
# size changes the navigation mesh and the cameras' eye height, so one map added by each would get
# two camera graphs. TrackSettings keeps Recast's 2.0 m and 0.6 m as the registry's and the HTTP
# API's defaults.
PLAYER_HEIGHT_M = 1.75
PLAYER_RADIUS_M = 0.5


def check(checks: list[tuple[bool, str]]) -> None:
    for ok, message in checks:
        if not ok:
            raise ValueError(message)


@dataclass(frozen=True)
class TrackSettings:
    # --- agent and derived navigation mesh (navmesh.py; Recast demo defaults) ---
    agent_height_m: float = 2.0              # head clearance an agent needs; also the actor height, m. [0.1, 100]
    agent_radius_m: float = 0.6              # walkable area is eroded by this from walls, m. [0, 50]
    agent_max_climb_m: float = 0.9           # steps up to this height connect walkable surfaces, m. [0, 50]
    agent_max_slope_deg: float = 45.0        # steepest walkable surface, deg. [0, 89]
    navmesh_cell_m: float = 0.6              # walkable triangles are split to edges at most this long before the clearance tests, m. [0.05, 20]
    min_region_area_m2: float = 5.76         # connected walkable regions smaller than this are dropped (Recast: 8^2 cells of 0.3 m), m^2. [0, 1e6]
    # --- skeleton (skeleton.py, Section 4.1) ---
    layer_cell_m: float = 0.5                # grid cell that detects floors overlapping in projection, m. [0.05, 20]
    skeleton_simplify_m: float = 0.4         # navmesh outline simplification before the straight skeleton, m. [0, 10]
    skeleton_min_hole_m2: float = 1.0        # outline holes smaller than this are filled (cracks, slivers, posts), m^2. [0, 1e4]
    skeleton_prune_m: float = 1.5            # a dead-end branch is pruned unless it reaches this far past its junction's clearance, m. [0, 100]
    skeleton_line_tolerance_m: float = 0.5   # skeleton chains are simplified (Douglas-Peucker) to this tolerance, m. [0, 10]
    # --- ray-cast sampling (sampling.py, Section 4.2) ---
    skeleton_spacing_m: float = 1.5          # distance between ray origins along the skeleton, m. [0.05, 50]
    eye_height_fraction: float = 0.9         # ray origins sit this far up the agent above the skeleton, fraction of agent height. [0, 2]
    ray_elevations_deg: tuple[float, ...] = (0.0, 30.0, -15.0, 90.0)  # eye level, high angle, low angle, bird's eye; each cast to both sides (90: once, straight up), deg. each in [-90, 90]
    epsilon_m: float = 0.4                   # a camera is placed this far before the surface its ray hits (the paper's epsilon), m. [0, 10]
    d_max_m: float = 10.0                    # a ray that hits nothing places its camera this far out (the paper's d_max), m. (0, 1000]
    min_camera_distance_m: float = 1.0       # samples nearer than this to their skeleton origin are dropped, m. [0, 100]
    include_skeleton_points: bool = True     # the skeleton points themselves join the cloud (Figure 6)
    footprint_margin_m: float = 3.0          # samples farther than this from the navmesh in (x, z) are dropped (ours), m. (0, 1e4]
    # --- sequential RANSAC (ransac.py, Section 4.3) ---
    ransac_threshold_m: float = 0.3          # consensus distance to the line (the paper's epsilon of CS), m. (0, 10]
    ransac_hypotheses: int = 128             # line hypotheses per extracted line. [1, 10000]
    ransac_score_subsample: int = 4096       # hypotheses are pre-scored on at most this many remaining points, the best 16 on all. [16, 1e7]
    ransac_pair_radius_m: float = 6.0        # the second point of a hypothesis is drawn within this of the first, m. (0, 1e4]
    ransac_min_inliers: int = 5              # sequential extraction stops when the best line has fewer inliers. [2, 1e6]
    ransac_max_lines: int = 4000             # at most this many lines (the paper's iteration count). [1, 1e6]
    max_inlier_gap_m: float = 4.0            # a track's consensus set is its line's largest run of inliers with no gap over this, m. (0, 1e4]
    # --- filters (filters.py, Section 4.4) ---
    filter_sequence: tuple[int, ...] = (1, 2, 3, 4, 1, 3)  # filters applied in this order; #1 again after the #4 refit. each in {1, 2, 3, 4}
    collision_min_piece_m: float = 0.25      # filter #1 stops splitting colliding pieces below this length, m. (0, 100]
    min_support_points: int = 1              # filter #3 drops tracks with fewer supporting points. [1, 1e6]
    # --- redundant tracks (redundancy.py, ours: the paper keeps every track) ---
    redundancy_k: int = 2                    # a track is dropped when each triangle it sees is seen by this many other kept tracks; 0 keeps all. [0, 1000]
    redundancy_range_m: float = 5.0          # triangles this close to a track point are seen near it; inside the long shot's framing tolerance (5.4 m), m. (0, 1e4]
    # --- camera navigation graph (graph.py, Section 4.6) ---
    intersection_tolerance_m: float = 0.3    # tracks passing closer than this intersect, m. [0, 10]
    max_edge_length_m: float = 10.0          # edges are split until no longer than this (step ii); under the director's 12 m candidate radius, so an edge passing the actor has a node near it, m. (0, 1e4]
    link_distance_m: float = 3.0             # nodes of different components closer than this and mutually visible are linked (step iii), m. [0, 1e4]
    # --- remeshing and dual visibility (visibility_table.py, Section 4.5) ---
    max_triangle_area_m2: float = 1.0        # navmesh triangles are split until no larger, m^2. (0, 1e6]
    visibility_range_m: float = 15.0         # node-triangle pairs further apart are not tested, m. (0, 1e4]
    visibility_rays: int = 4                 # Monte Carlo rays per node-triangle pair. [1, 256]
    visibility_target_height_fraction: float = 0.5  # rays aim this far up the agent above random triangle points, fraction of agent height. [0, 2]

    def __post_init__(self):
        check([
            (0.1 <= self.agent_height_m <= 100.0, "agent_height_m must be in [0.1, 100]"),
            (0.0 <= self.agent_radius_m <= 50.0, "agent_radius_m must be in [0, 50]"),
            (0.0 <= self.agent_max_climb_m <= 50.0, "agent_max_climb_m must be in [0, 50]"),
            (0.0 <= self.agent_max_slope_deg <= 89.0, "agent_max_slope_deg must be in [0, 89]"),
            (0.05 <= self.navmesh_cell_m <= 20.0, "navmesh_cell_m must be in [0.05, 20]"),
            (0.0 <= self.min_region_area_m2 <= 1e6, "min_region_area_m2 must be in [0, 1e6]"),
            (0.05 <= self.layer_cell_m <= 20.0, "layer_cell_m must be in [0.05, 20]"),
            (0.0 <= self.skeleton_simplify_m <= 10.0, "skeleton_simplify_m must be in [0, 10]"),
            (0.0 <= self.skeleton_min_hole_m2 <= 1e4, "skeleton_min_hole_m2 must be in [0, 1e4]"),
            (0.0 <= self.skeleton_prune_m <= 100.0, "skeleton_prune_m must be in [0, 100]"),
            (0.0 <= self.skeleton_line_tolerance_m <= 10.0, "skeleton_line_tolerance_m must be in [0, 10]"),
            (0.05 <= self.skeleton_spacing_m <= 50.0, "skeleton_spacing_m must be in [0.05, 50]"),
            (0.0 <= self.eye_height_fraction <= 2.0, "eye_height_fraction must be in [0, 2]"),
            (len(self.ray_elevations_deg) >= 1 and all(-90.0 <= e <= 90.0 for e in self.ray_elevations_deg),
             "ray_elevations_deg must hold at least one angle in [-90, 90]"),
            (0.0 <= self.epsilon_m <= 10.0, "epsilon_m must be in [0, 10]"),
            (0.0 < self.d_max_m <= 1000.0, "d_max_m must be in (0, 1000]"),
            (0.0 < self.footprint_margin_m <= 1e4, "footprint_margin_m must be in (0, 1e4]"),
            (0.0 <= self.min_camera_distance_m <= 100.0, "min_camera_distance_m must be in [0, 100]"),
            (0.0 < self.ransac_threshold_m <= 10.0, "ransac_threshold_m must be in (0, 10]"),
            (1 <= self.ransac_hypotheses <= 10_000, "ransac_hypotheses must be in [1, 10000]"),
            (16 <= self.ransac_score_subsample <= 10_000_000, "ransac_score_subsample must be in [16, 1e7]"),
            (0.0 < self.ransac_pair_radius_m <= 1e4, "ransac_pair_radius_m must be in (0, 1e4]"),
            (2 <= self.ransac_min_inliers <= 1_000_000, "ransac_min_inliers must be in [2, 1e6]"),
            (1 <= self.ransac_max_lines <= 1_000_000, "ransac_max_lines must be in [1, 1e6]"),
            (0.0 < self.max_inlier_gap_m <= 1e4, "max_inlier_gap_m must be in (0, 1e4]"),
            (all(f in (1, 2, 3, 4) for f in self.filter_sequence), "filter_sequence holds filter numbers 1 to 4"),
            (0.0 < self.collision_min_piece_m <= 100.0, "collision_min_piece_m must be in (0, 100]"),
            (1 <= self.min_support_points <= 1_000_000, "min_support_points must be in [1, 1e6]"),
            (0 <= self.redundancy_k <= 1000, "redundancy_k must be in [0, 1000]"),
            (0.0 < self.redundancy_range_m <= 1e4, "redundancy_range_m must be in (0, 1e4]"),
            (0.0 <= self.intersection_tolerance_m <= 10.0, "intersection_tolerance_m must be in [0, 10]"),
            (0.0 < self.max_edge_length_m <= 1e4, "max_edge_length_m must be in (0, 1e4]"),
            (0.0 <= self.link_distance_m <= 1e4, "link_distance_m must be in [0, 1e4]"),
            (0.0 < self.max_triangle_area_m2 <= 1e6, "max_triangle_area_m2 must be in (0, 1e6]"),
            (0.0 < self.visibility_range_m <= 1e4, "visibility_range_m must be in (0, 1e4]"),
            (1 <= self.visibility_rays <= 256, "visibility_rays must be in [1, 256]"),
            (0.0 <= self.visibility_target_height_fraction <= 2.0,
             "visibility_target_height_fraction must be in [0, 2]"),
        ])
