"""Settings of the camera tracks: one typed object for the precompute, one for the runtime director.

Defaults are the paper's where it gives a value (Section 5.1: occlusion and framing violations
trigger a cut after 200 ms; Section 5.3: the 30-degree rule) and Recast's demo defaults for the
agent and the derived navigation mesh (agent height 2.0 m, radius 0.6 m, climb 0.9 m, slope 45
deg, regions under 8 x 8 cells of 0.3 m dropped). Every other value is our choice, documented on
its line and in the module that uses it. All lengths are metres (after the level's scale), angles
degrees where the name says `_deg`, times seconds.
"""
from __future__ import annotations

from dataclasses import dataclass


def _check(checks: list[tuple[bool, str]]) -> None:
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
        _check([
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


@dataclass(frozen=True)
class DirectorSettings:
    # --- lens and actor (scoring.py) ---
    vertical_fov_deg: float = 50.0           # the lens the shot sizes are computed for, deg. (1, 170)
    actor_sample_fractions: tuple[float, ...] = (0.15, 0.5, 0.9)  # points up the actor tested for direct visibility, fraction of its height. each in [0, 1]
    look_at_fraction: float = 0.6            # the camera looks at this point up the actor, fraction of its height. [0, 1]
    actor_radius_fraction: float = 0.15      # the actor's half-width that framing keeps in frame, fraction of its height (shoulders). [0, 1]
    # --- shot sizes: actor height on screen / frame height (Section 6.1) ---
    medium_shot_screen_fraction: float = 1.4     # waist up (half the body) fills 0.7 of the frame: at 1.6 the waist-up, with the
                                                 # body's girth nearer the camera, left the frame at the optimal distance. (0, 10]
    long_shot_screen_fraction: float = 0.8       # the whole body fills most of the frame. (0, 10]
    extreme_long_shot_screen_fraction: float = 0.25  # the actor is small in the set. (0, 10]
    shot_size_tolerance_log: float = 0.4     # Gaussian width of the shot-size sub-score in ln(distance ratio). (0, 5]
    framing_violation_log: float = 0.7       # framing is violated when |ln(distance / optimal)| exceeds this. (0, 5]
    frame_margin: float = 0.1                # the framed extent's ends stay this far inside the frame's edges (framing.py), normalised screen units. [0, 0.9]
    fit_softness: float = 0.2                # the shot-size sub-score falls to 0 as the extent's fit ratio goes from 1 to 1 + this. (0, 10]
    # --- target moving strategy (target_search.py, Section 5.2) ---
    candidate_radius_m: float = 12.0         # candidate edges touch a node at most this far from the actor, m. (0, 1e4]
    max_graph_distance_m: float = 25.0       # A* gives up beyond this; the distance sub-score is 0 there, m. (0, 1e5]
    visibility_lookahead_s: float = 1.0     # places are scored on the actor now and this far ahead on its velocity (the worse), s. [0, 10]
    surroundings_radius_m: float = 3.0       # navmesh triangles this close to the actor make its surroundings (indirect visibility), m. (0, 100]
    descent_step_m: float = 0.25             # local descent moves along edges by this, m. (0, 100]
    descent_max_steps: int = 8               # local descent stops after this many moves. [0, 1000]
    weight_shot_size: float = 1.0            # sub-score weights (the framing strategy). each in [0, 100]
    weight_direct_visibility: float = 2.0
    weight_indirect_visibility: float = 1.0
    weight_distance: float = 1.0
    # --- cutting strategy (cutting.py, Section 5.1) ---
    shot_duration_median_s: float = 4.0      # median of the log-normal shot-duration model, s. (0, 3600]
    shot_duration_sigma: float = 0.5         # sigma of ln(duration) of that model. (0, 5]
    min_shot_s: float = 1.0                  # no cut for any reason before a shot is this old, s. [0, 60]
    occlusion_cut_s: float = 0.2             # occlusion longer than this triggers a cut (paper: 200 ms), s. [0, 60]
    framing_cut_s: float = 0.2               # framing violated longer than this triggers a cut (paper: 200 ms), s. [0, 60]
    framing_cut_margin: float = 0.5          # cuts go first to places within this share of framing_violation_log
                                             # (one at its edge is violated again a moment later), fraction. (0, 1]
    occluded_below_fraction: float = 0.5     # the actor counts as occluded when fewer of its points are visible, fraction. (0, 1]
    # --- continuity rules (continuity.py, Section 5.3) ---
    min_cut_angle_deg: float = 30.0          # the 30-degree rule, deg. [0, 180]
    weight_thirty_degree: float = 1.0        # cut-specific sub-score weights. each in [0, 100]
    weight_line_of_action: float = 1.0
    min_actor_speed_m_s: float = 0.2         # below this the line of action follows the actor's facing, m/s. [0, 100]
    # --- camera motion (camera_motion.py, Section 5.4) ---
    attraction_per_s2: float = 6.0           # spring constant towards the target (mass 1), 1/s^2. (0, 1e4]
    damping_ratio: float = 1.0               # 1 = critical damping: no overshoot. [0, 10]
    repulsion_radius_m: float = 1.0          # the actor pushes the camera away inside at least this distance (director.py), m. [0, 100]
    repulsion_m_s2: float = 20.0             # repulsion acceleration at zero distance, m/s^2. [0, 1e4]
    max_speed_m_s: float = 6.0               # camera speed limit, m/s. (0, 1000]
    max_substep_s: float = 1.0 / 60.0        # the force integration takes steps no longer than this, s. (0, 1]

    def __post_init__(self):
        weights = (self.weight_shot_size, self.weight_direct_visibility, self.weight_indirect_visibility,
                   self.weight_distance, self.weight_thirty_degree, self.weight_line_of_action)
        _check([
            (1.0 < self.vertical_fov_deg < 170.0, "vertical_fov_deg must be in (1, 170)"),
            (len(self.actor_sample_fractions) >= 1 and all(0.0 <= f <= 1.0 for f in self.actor_sample_fractions),
             "actor_sample_fractions must hold at least one fraction in [0, 1]"),
            (0.0 <= self.look_at_fraction <= 1.0, "look_at_fraction must be in [0, 1]"),
            (0.0 <= self.actor_radius_fraction <= 1.0, "actor_radius_fraction must be in [0, 1]"),
            (all(0.0 < f <= 10.0 for f in (self.medium_shot_screen_fraction, self.long_shot_screen_fraction,
                                          self.extreme_long_shot_screen_fraction)),
             "shot screen fractions must be in (0, 10]"),
            (0.0 < self.shot_size_tolerance_log <= 5.0, "shot_size_tolerance_log must be in (0, 5]"),
            (0.0 < self.framing_violation_log <= 5.0, "framing_violation_log must be in (0, 5]"),
            (0.0 <= self.frame_margin <= 0.9, "frame_margin must be in [0, 0.9]"),
            (0.0 < self.fit_softness <= 10.0, "fit_softness must be in (0, 10]"),
            (0.0 < self.candidate_radius_m <= 1e4, "candidate_radius_m must be in (0, 1e4]"),
            (0.0 < self.max_graph_distance_m <= 1e5, "max_graph_distance_m must be in (0, 1e5]"),
            (0.0 <= self.visibility_lookahead_s <= 10.0, "visibility_lookahead_s must be in [0, 10]"),
            (0.0 < self.surroundings_radius_m <= 100.0, "surroundings_radius_m must be in (0, 100]"),
            (0.0 < self.descent_step_m <= 100.0, "descent_step_m must be in (0, 100]"),
            (0 <= self.descent_max_steps <= 1000, "descent_max_steps must be in [0, 1000]"),
            (all(0.0 <= w <= 100.0 for w in weights) and sum(weights) > 0.0,
             "weights must be in [0, 100] and not all 0"),
            (0.0 < self.shot_duration_median_s <= 3600.0, "shot_duration_median_s must be in (0, 3600]"),
            (0.0 < self.shot_duration_sigma <= 5.0, "shot_duration_sigma must be in (0, 5]"),
            (0.0 <= self.min_shot_s <= 60.0, "min_shot_s must be in [0, 60]"),
            (0.0 <= self.occlusion_cut_s <= 60.0, "occlusion_cut_s must be in [0, 60]"),
            (0.0 <= self.framing_cut_s <= 60.0, "framing_cut_s must be in [0, 60]"),
            (0.0 < self.framing_cut_margin <= 1.0, "framing_cut_margin must be in (0, 1]"),
            (0.0 < self.occluded_below_fraction <= 1.0, "occluded_below_fraction must be in (0, 1]"),
            (0.0 <= self.min_cut_angle_deg <= 180.0, "min_cut_angle_deg must be in [0, 180]"),
            (0.0 <= self.min_actor_speed_m_s <= 100.0, "min_actor_speed_m_s must be in [0, 100]"),
            (0.0 < self.attraction_per_s2 <= 1e4, "attraction_per_s2 must be in (0, 1e4]"),
            (0.0 <= self.damping_ratio <= 10.0, "damping_ratio must be in [0, 10]"),
            (0.0 <= self.repulsion_radius_m <= 100.0, "repulsion_radius_m must be in [0, 100]"),
            (0.0 <= self.repulsion_m_s2 <= 1e4, "repulsion_m_s2 must be in [0, 1e4]"),
            (0.0 < self.max_speed_m_s <= 1000.0, "max_speed_m_s must be in (0, 1000]"),
            (0.0 < self.max_substep_s <= 1.0, "max_substep_s must be in (0, 1]"),
        ])
