"""Settings of the motion overview: one typed object, defaults with unit and limit, validated once.

Defaults are the paper's where it gives a value (Section 4: c1..c5 = 10, 10, 5, 5, 2; speed limit
height/6, angular speed 20 deg, friction height/20; split below 70% quality among frames below 80%
saliency; up to 6 shots per 1000 frames). Every other value is our choice, documented here and in
the module that uses it. Lengths are in character heights ("_heights") so one setting fits any
skeleton; the pipeline converts them to metres once, from `MotionClip.character_height_m`.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class OverviewSettings:
    # --- time base (pipeline.py) ---
    analysis_rate_hz: float = 15.0           # rate the stages run at; the path is interpolated back to the clip's rate, Hz. [1, 240]
    # --- motion saliency (saliency.py, Section 3 after Assa et al. 2005) ---
    mds_dimensions: int = 3                  # dimension of the non-linear MDS curve. [1, 10]
    mds_iterations: int = 10                 # Sammon-mapping iterations after the classical-MDS start (most of the gain comes first). [0, 1000]
    speed_feature_time_s: float = 0.2        # joint velocities are multiplied by this to weigh them against positions, s. [0, 10]
    saliency_smoothing_s: float = 0.5        # Gaussian sigma of the smooth average curve, s. (0, 30]
    limb_contrast_ratio: float = 2.0         # max/mean limb saliency at which limb weights are fully used (below: toward uniform). (1, 100]
    # --- viewpoint quality (viewpoint_quality.py, Section 3) ---
    three_quarter_angle_deg: float = 45.0    # preferred horizontal angle between the character's front and the camera, deg. [0, 180]
    three_quarter_width_deg: float = 45.0    # Gaussian width of that preference, deg. (0, 180]
    moving_speed_heights_s: float = 0.25     # character speed at which the perpendicular-to-motion descriptor has full weight, heights/s. (0, 10]
    preferred_distance_heights: float = 2.0  # camera distance the distance descriptor prefers, heights. (0, 20]
    distance_tolerance_log: float = 0.35     # Gaussian width of the distance descriptor in log(distance ratio). (0, 5]
    wide_max_eigen_ratio: float = 0.5        # lambda3/lambda2 at and above which the widest aspect is not considered. (0, 1]
    occlusion_points: int = 6                # character points tested for scene occlusion (root, head, hands, feet). [1, 6]
    # --- limb visibility rendering (limb_visibility.py, Section 3 and Figure 7) ---
    limb_view_azimuths: int = 12             # view directions around the character per elevation. [4, 72]
    limb_view_elevations_deg: tuple[float, ...] = (-10.0, 15.0, 40.0)  # elevations rendered, deg. each in [-89, 89], increasing
    limb_tile_px: int = 64                   # square render size per view, pixels. [16, 256]
    limb_min_saliency: float = 0.3           # frames with pose saliency below this are not rendered (E_wide stands in). [0, 1]
    head_radius_heights: float = 0.065       # ellipsoid radius of the head, heights. (0, 0.5]
    torso_radius_heights: float = 0.10       # ellipsoid radius across torso bones, heights. (0, 0.5]
    arm_radius_heights: float = 0.03         # ellipsoid radius across arm bones, heights. (0, 0.5]
    leg_radius_heights: float = 0.045        # ellipsoid radius across leg bones, heights. (0, 0.5]
    # --- candidate camera positions (potential.py, Section 3 "viewpoint potential space") ---
    grid_spacing_heights: float = 0.3        # horizontal spacing of candidate positions, heights. [0.05, 2]
    camera_heights_heights: tuple[float, ...] = (0.3, 0.65, 1.0, 1.35)  # candidate camera heights above the floor, heights. each in [0.05, 5], increasing
    grid_margin_heights: float = 3.5         # candidate space extends this far beyond the character's path, heights. [1, 20]
    max_vertical_fov_deg: float = 70.0       # widest lens a shot may need; sets the closest allowed distance, deg. (5, 150)
    aspect: float = 16.0 / 9.0               # frame width / height. [0.2, 5]
    frame_margin: float = 0.1                # fraction of the half-frame kept free around the silhouette. [0, 0.5)
    clearance_heights: float = 0.25          # extra gap between the camera and the character's bounding box, heights. [0, 2]
    look_at_smoothing_s: float = 0.3         # Gaussian sigma of the look-at point (character centre), s. [0, 5]
    # --- path energy and quantum annealing (energy.py, annealing.py, Section 4) ---
    c1: float = 10.0                         # acceleration weight. [0, 1e6]
    c2: float = 10.0                         # speed-limit weight. [0, 1e6]
    c3: float = 5.0                          # angular acceleration weight. [0, 1e6]
    c4: float = 5.0                          # angular speed-limit weight. [0, 1e6]
    c5: float = 2.0                          # friction weight. [0, 1e6]
    max_speed_heights_s: float = 1.0 / 6.0          # S_max, heights/s. (0, 100]
    max_angular_speed_deg_s: float = 20.0           # alpha_max, deg/s. (0, 3600]
    friction_speed_heights_s: float = 1.0 / 20.0    # F_max, heights/s. (0, 100]
    annealing_iterations_per_frame: float = 6.0     # proposals per analysis frame of a shot. [0.1, 1000]
    annealing_min_iterations: int = 3000            # proposals per shot at least, whatever its length. [1, 10^6]
    initial_neighbourhood_heights: float = 3.5      # first neighbourhood size (L1), heights; the grid margin, so a rigid neighbour can cross it ("starts high"). (0, 50]
    final_neighbourhood_heights: float = 0.02       # discretisation threshold where annealing stops, heights. (0, initial)
    # --- shot splitting (shots.py, Section 4) ---
    split_quality: float = 0.70              # a shot whose saliency-weighted quality is below this is split. [0, 1]
    split_max_saliency: float = 0.80         # only frames with pose saliency below this may take the cut. [0, 1]
    min_shot_s: float = 2.0                  # no shot shorter than this, s. [0.1, 600]
    max_shots_per_1000_frames: float = 6.0   # cap on shots, per 1000 frames of the clip. [1, 1000]
    # --- baselines (baselines.py, Section 5) ---
    greedy_smoothing_s: float = 1.0          # Gaussian sigma that smooths the per-frame greedy path, s. (0, 30]

    def __post_init__(self):
        el = self.limb_view_elevations_deg
        hs = self.camera_heights_heights
        checks = [
            (1.0 <= self.analysis_rate_hz <= 240.0, "analysis_rate_hz must be in [1, 240]"),
            (1 <= self.mds_dimensions <= 10, "mds_dimensions must be in [1, 10]"),
            (0 <= self.mds_iterations <= 1000, "mds_iterations must be in [0, 1000]"),
            (0.0 <= self.speed_feature_time_s <= 10.0, "speed_feature_time_s must be in [0, 10]"),
            (0.0 < self.saliency_smoothing_s <= 30.0, "saliency_smoothing_s must be in (0, 30]"),
            (1.0 < self.limb_contrast_ratio <= 100.0, "limb_contrast_ratio must be in (1, 100]"),
            (0.0 <= self.three_quarter_angle_deg <= 180.0, "three_quarter_angle_deg must be in [0, 180]"),
            (0.0 < self.three_quarter_width_deg <= 180.0, "three_quarter_width_deg must be in (0, 180]"),
            (0.0 < self.moving_speed_heights_s <= 10.0, "moving_speed_heights_s must be in (0, 10]"),
            (0.0 < self.preferred_distance_heights <= 20.0, "preferred_distance_heights must be in (0, 20]"),
            (0.0 < self.distance_tolerance_log <= 5.0, "distance_tolerance_log must be in (0, 5]"),
            (0.0 < self.wide_max_eigen_ratio <= 1.0, "wide_max_eigen_ratio must be in (0, 1]"),
            (1 <= self.occlusion_points <= 6, "occlusion_points must be in [1, 6]"),
            (4 <= self.limb_view_azimuths <= 72, "limb_view_azimuths must be in [4, 72]"),
            (len(el) >= 2 and all(-89.0 <= e <= 89.0 for e in el)
             and all(a < b for a, b in zip(el, el[1:])),
             "limb_view_elevations_deg must be at least two increasing values in [-89, 89]"),
            (16 <= self.limb_tile_px <= 256, "limb_tile_px must be in [16, 256]"),
            (0.0 <= self.limb_min_saliency <= 1.0, "limb_min_saliency must be in [0, 1]"),
            (all(0.0 < r <= 0.5 for r in (self.head_radius_heights, self.torso_radius_heights,
                                           self.arm_radius_heights, self.leg_radius_heights)),
             "body part radii must be in (0, 0.5] heights"),
            (0.05 <= self.grid_spacing_heights <= 2.0, "grid_spacing_heights must be in [0.05, 2]"),
            (len(hs) >= 2 and all(0.05 <= h <= 5.0 for h in hs) and all(a < b for a, b in zip(hs, hs[1:])),
             "camera_heights_heights must be at least two increasing values in [0.05, 5]"),
            (1.0 <= self.grid_margin_heights <= 20.0, "grid_margin_heights must be in [1, 20]"),
            (5.0 < self.max_vertical_fov_deg < 150.0, "max_vertical_fov_deg must be in (5, 150)"),
            (0.2 <= self.aspect <= 5.0, "aspect must be in [0.2, 5]"),
            (0.0 <= self.frame_margin < 0.5, "frame_margin must be in [0, 0.5)"),
            (0.0 <= self.clearance_heights <= 2.0, "clearance_heights must be in [0, 2]"),
            (0.0 <= self.look_at_smoothing_s <= 5.0, "look_at_smoothing_s must be in [0, 5]"),
            (all(0.0 <= c <= 1e6 for c in (self.c1, self.c2, self.c3, self.c4, self.c5)),
             "c1..c5 must be in [0, 1e6]"),
            (0.0 < self.max_speed_heights_s <= 100.0, "max_speed_heights_s must be in (0, 100]"),
            (0.0 < self.max_angular_speed_deg_s <= 3600.0, "max_angular_speed_deg_s must be in (0, 3600]"),
            (0.0 < self.friction_speed_heights_s <= 100.0, "friction_speed_heights_s must be in (0, 100]"),
            (0.1 <= self.annealing_iterations_per_frame <= 1000.0, "annealing_iterations_per_frame must be in [0.1, 1000]"),
            (1 <= self.annealing_min_iterations <= 1_000_000, "annealing_min_iterations must be in [1, 10^6]"),
            (0.0 < self.initial_neighbourhood_heights <= 50.0, "initial_neighbourhood_heights must be in (0, 50]"),
            (0.0 < self.final_neighbourhood_heights < self.initial_neighbourhood_heights,
             "final_neighbourhood_heights must be in (0, initial_neighbourhood_heights)"),
            (0.0 <= self.split_quality <= 1.0, "split_quality must be in [0, 1]"),
            (0.0 <= self.split_max_saliency <= 1.0, "split_max_saliency must be in [0, 1]"),
            (0.1 <= self.min_shot_s <= 600.0, "min_shot_s must be in [0.1, 600]"),
            (1.0 <= self.max_shots_per_1000_frames <= 1000.0, "max_shots_per_1000_frames must be in [1, 1000]"),
            (0.0 < self.greedy_smoothing_s <= 30.0, "greedy_smoothing_s must be in (0, 30]"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)
