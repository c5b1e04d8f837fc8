"""Settings of the TRACKS rig's runtime director: one typed object, each default with its unit and
limit, validated once.

Defaults are the paper's where it gives a value (Section 5.1: occlusion and framing violations
trigger a cut after 200 ms; Section 5.3: the 30-degree rule); every other value is our choice,
documented on its line and in the module that uses it. Lengths are metres, angles degrees where the
name says `_deg`, times seconds.
"""
from __future__ import annotations

from dataclasses import dataclass

from camdirector.precompute.tracks.track_settings import check


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

    def __post_init__(self) -> None:
        weights = (self.weight_shot_size, self.weight_direct_visibility, self.weight_indirect_visibility,
                   self.weight_distance, self.weight_thirty_degree, self.weight_line_of_action)
        check([
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
