"""The match director's settings: one typed object, each default with its unit and limit, validated once.

The shot lengths that a caster styles (min and max shot) live in `Style` (style.py: `min_shot_s`,
`max_shot_s`, defaults 2 s and 8 s, the issue's); everything here is the director's own tuning.
`HltvSettings` holds the published rules of Valve's SourceTV director (hltvdirector.cpp and
hltvcamera.cpp of the Source SDK 2013), converted once from Source units (inches) to metres.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

from camdirector.pipeline.inputs import EventKind

INCH_M = 0.0254  # one Source unit: the SDK's player is 72 units tall (1.83 m)


@dataclass(frozen=True)
class HltvSettings:
    rank_interval_s: float = 0.5         # players and fixed cameras are ranked this often, s. (0, 10]
    min_shot_s: float = 4.0              # MIN_SHOT_LENGTH: shorter time to the next forced cut extends the shot, s. (0, 60]
    max_shot_s: float = 8.0              # MAX_SHOT_LENGTH, s. [min_shot_s, 120]
    default_shot_s: float = 6.0          # DEF_SHOT_LENGTH: a random shot's length, s. [min_shot_s, max_shot_s]
    min_director_delay_s: float = 10.0   # HLTV_MIN_DIRECTOR_DELAY: below it no look-ahead, s. [0, 300]
    event_window_s: float = 2.0          # the look-ahead is four windows of this length, s. (0, 10]
    after_event_s: float = 2.0           # the next cut comes this long after a shown kill, s. [0, 10]
    rank_range_m: float = 1024 * INCH_M  # players farther apart than this do not rank each other, m. (0, 1000]
    kill_chase_distance_m: float = 96 * INCH_M    # the kill's chase camera behind its first target, m. (0, 100]
    kill_chase_pitch_deg: float = -20.0  # Source pitch (positive looks down): -20 is the low, dramatic view, deg. [-89, 89]
    kill_chase_yaw_deg: float = 30.0     # left or right of the line to the second target, at random, deg. [0, 180]
    player_chase_distance_m: float = 112 * INCH_M  # the best player's chase camera, m. (0, 100]
    player_chase_pitch_deg: float = 20.0  # deg. [-89, 89]
    player_chase_yaw_deg: float = 20.0    # deg. [0, 180]
    dead_pitch_deg: float = 15.0         # pitch offset when the first target is dead, deg. [-89, 89]
    max_pitch_deg: float = 60.0          # the two-target chase camera's pitch clamp, deg. [0, 89]
    wall_hull_half_m: float = 6 * INCH_M  # the chase camera's wall trace sweeps a box this half wide (hltvcamera.cpp
                                         # WALL_OFFSET, C_HLTVCamera::CalcChaseCamView's UTIL_TraceHull), m. [0, 1]
    angle_inertia_per_s: float = 3.0     # a turning view closes this share of its gap a second (m_flInertia, 3 unless
                                         # hltv_chase sets it; C_HLTVCamera::SmoothCameraAngle), 1/s. (0, 1000]
    fixed_camera_share: float = 0.25     # with no event, a fixed camera this often, else a chase. [0, 1]
    in_eye_kill_chance: float = 0.67     # a kill is shown first person this often (the SDK: > 0.33). [0, 1]
    swap_chance_in_eye: float = 0.7      # first person: the attacker's eyes this often. [0, 1]
    swap_chance_chase: float = 0.3       # chase: behind the attacker instead of the victim this often. [0, 1]
    priorities: dict[EventKind, int] = field(default_factory=lambda: {
        EventKind.KILL: 7, EventKind.DAMAGE: 5, EventKind.OBJECTIVE: 6})
                                         # the only kinds the director hears (CHLTVDirector::SetHLTVServer listens for
                                         # player_death, player_hurt, round_start and round_end), each with the priority
                                         # the SDK fires it with: player_death 7 (multiplay_gamerules.cpp:887,
                                         # CMultiplayRules::DeathNotice), player_hurt 5 (player.cpp:1647,
                                         # CBasePlayer::OnTakeDamage_Alive), round_start 6 (hl2mp_gamerules.cpp:1056,
                                         # CHL2MPRules::RestartGame), [1, 15]

    def __post_init__(self) -> None:
        _check_positive_finite(self, ("rank_interval_s", "min_shot_s", "event_window_s", "rank_range_m",
                                      "kill_chase_distance_m", "player_chase_distance_m", "angle_inertia_per_s"))
        if not self.min_shot_s <= self.default_shot_s <= self.max_shot_s:
            raise ValueError("HltvSettings: need min_shot_s <= default_shot_s <= max_shot_s")
        if self.wall_hull_half_m > 1.0 or self.angle_inertia_per_s > 1000.0:
            raise ValueError("HltvSettings: need wall_hull_half_m in [0, 1] m and angle_inertia_per_s in (0, 1000] /s, "
                             f"got {self.wall_hull_half_m} and {self.angle_inertia_per_s}")
        if not set(self.priorities) <= set(EventKind) or not all(1 <= p <= 15 for p in self.priorities.values()):
            raise ValueError("HltvSettings: priorities maps EventKinds to priorities in [1, 15]")
        for name in ("fixed_camera_share", "in_eye_kill_chance", "swap_chance_in_eye", "swap_chance_chase"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"HltvSettings: {name} must be in [0, 1]")


@dataclass(frozen=True)
class MatchSettings:
    plan_rate_hz: float = 10.0           # the planner's rate; the program camera runs every frame, Hz. (0, 120]
    plan_work_per_tick: float = 1.0e5    # a drawn plan is applied at the first tick by which it needed at most this much
                                         # work per tick since it was drawn (rig.py; about 30 ms here; the idle moments of a
                                         # tick at 30 Hz compute three times that), camera-point pairs. [1e3, 1e9]
    lead_s: float = 2.5                  # preferred cut before a planned event, s. [min_lead_s, max_lead_s]
    min_lead_s: float = 0.5              # no cut in the last half second before a planned event (the pair window
                                         # opens then; at 1.0 s the real 4on4's kills under 1.5 s apart lost theirs:
                                         # kill coverage 0.534 -> 0.575), s. [0, 10]
    max_lead_s: float = 4.0              # never cut for an event earlier than this before it, s. [min_lead_s, 30]
    lookahead_s: float = 12.0            # the planner reads the buffered future this far, s. (0, 300]
    beat_min_priority: int = 5           # events of this priority or more get a planned shot (kills, objectives). [1, 15]
    max_group: int = 4                   # most players in one shot. [2, 64]
    join_spread_max_m: float = 15.0      # events join one shot only when their players stand this close: a GROUP 15 m wide
                                         # frames them at about 0.17 of the frame's height; on the open nav_test, joins of
                                         # players 24 m apart showed them at 0.03-0.07 (median height 0.066), m. (0, 1000]
    preferred_shot_s: float = 3.0        # a planned cut that would end the shot before it sooner than this is not made when one
                                         # GROUP or OVERVIEW shows both beats (kills 2.7 s apart made 2.7-s shots), s. [0, 60]
    max_held_shot_s: float = 16.0        # a shot that shows the players of the next event is held for it only this long from
                                         # its cut; later, the event gets a cut of its own (the real duel's pair is in every
                                         # kill: one shot held 26 s, a kill in it unseen), s. (0, 600]
    event_hold_s: float = 0.2            # a shown event stays on screen this long before a planned cut to the next
                                         # (eval-match: at 1.0 s, the next kill elsewhere lost its lead; nav_test
                                         # coverage 0.80 at 0.2 s, 0.76 at 0.5 s), s. [0, 10]
    pair_before_s: float = 0.5          # a planned DUEL frames its pair from this long before each of its events (before, the
                                         # killer alone: shots.py PairWindow), s. [0, 30]
    pair_after_s: float = 0.25           # to this long after it, s. [0, 30]
    reframe_s: float = 0.5               # easing between the pair and the killer alone, s. (0, 10]
    replay_pre_s: float = 2.0            # a REPLAY shows its kill again from this long before it (the build-up: replays.py), s.
                                         # [0, 10]
    replay_post_s: float = 0.5           # to this long after it; with replay_pre_s at least the style's min_shot_s, s. [0, 10]
    replay_after_s: float = 1.0          # and no sooner than this after it: the live shot first follows the survivor once the
                                         # pair's window closes (pair_after_s and reframe_s), s. [0, replay_within_s]
    replay_within_s: float = 4.0         # a kill is replayed only this soon after it (later, the program has moved on; the
                                         # buffer keeps replay_within_s + replay_pre_s of past for it), s. [0, 30]
    dead_hold_s: float = 1.5             # after that long on a dead subject the director cuts away, s. [0, 10]
    respawn_speed_m_s: float = 30.0      # a dead player's feet moving faster than this between two frames teleported: a respawn
                                         # (runners 5-8 m/s, a body falling 45 m reaches 30 m/s), m/s. (0, 10000]
    respawn_min_jump_m: float = 0.5      # and at least this far (rounding and interpolation stay under it), m. (0, 1000]
    respawn_walk_m: float = 5.0          # a dead player this far from where it fell has walked away: respawned in place, m. (0, 1000]
    engage_range_m: float = 25.0         # opponents farther apart do not fight, m. (0, 1000]
    facing_cos: float = 0.5              # a player faces another within acos(0.5) = 60 deg of its forward. [-1, 1]
    recent_event_s: float = 3.0          # a damage event makes its pair a fight for this long, s. [0, 30]
    switch_margin: float = 0.5           # a discretionary cut needs a shot this much better (relative). [0, 10]
    settle_s: float = 4.0                # and the shot this old (hysteresis; dead subjects and max shot cut sooner), s. [0, 120]
    group_radius_m: float = 8.0          # players within this of their centroid make a GROUP, m. (0, 100]
    overview_min_interest: float = 0.15  # below this best interest the director shows an OVERVIEW. [0, 100]
    samples_per_player: int = 16         # surface points ray-cast per framed player (8 misjudged half-hidden players). [1, 256]
    min_visible: float = 0.75            # a framed place under this visible share looks for a better one. [0, 1]
    candidates: int = 3                  # preview shots offered beside the program. [0, 16]
    edit_window_s: float = 2.5           # the rig works the program this far ahead of the moment it answers, at most a
                                         # quarter of the delay, and gives a shot shorter than the style's min_shot_s
                                         # to a neighbour there, or starts it earlier in what the window holds beyond
                                         # min_shot_s (edit_window.py); 0: none, s. [0, 10]
    edit_lengthen_s: float = 2.4         # a shot the style's min_shot_s long but under this is given to a neighbour too, where
                                         # that one shows its subjects in its frame as the shot did (edit_window.py SHOWN),
                                         # and a short shot started earlier is made this long: the real 2on2 had 13 of its
                                         # 48 shots at 2.0-2.13 s, its median 2.7 s (3.13 s with it); at most the window, s.
                                         # [0, 10]
    jump_cut_deg: float = 30.0           # the 30-degree rule: a cut on a shared subject turns the view this much, deg. [0, 180]
    overview_height_m: float = 12.0      # the bounding-box overview's height above the players, m. (0, 1000]
    pull_below: float = 0.5              # a camera that sees less than this share of its first subject's points (the rest
                                         # behind walls) comes in front of the wall; on the line to the aim point alone, a
                                         # ledge hiding the chest pulled in cameras that saw most of the body. [0, 1]
    pull_margin_m: float = 0.3           # and stops this far short of the wall (HLTV's wall margin), m. [0, 5]
    pull_regrow_m_s: float = 2.0         # and goes back out toward its place this fast (real players run 10 m/s past
                                         # corners; HLTV's 0.8 m/s held cameras pulled in for seconds), m/s. (0, 100]
    wall_hold_max_m: float = 4.0         # a program camera whose move into a new frame passes through a wall, and that no
                                         # place on its subject's side replaces, stays where it was (turning to frame)
                                         # if the move is this short; a longer one is a cut, m. [0, 100]
    move_speed_max_m_s: float = 40.0     # our director's Toric camera moving with no cut goes no faster than this (but for
                                         # a step back from a player then at its lens), the rest of a farther move made up
                                         # over the next frames (in_level.py `paced`): eval-match counts a move over
                                         # 60 m/s a cut no flag names; players run 10 m/s, rocket-jump 20-30, m/s. (0, 1000]
    move_cut_s: float = 0.25             # a farther move than this speed makes in this long is a cut instead where the shot
                                         # on air is min_shot_s long or an event it covers comes before the pace is done
                                         # (a dolly across the arena shows a kill from nowhere; 10 m at 40 m/s), s. [0, 10]
    seen_again_gap_s: float = 1.0        # a program camera that a degrade (pulled in front of a wall, held before one) left
                                         # showing none of its subjects is re-placed at once by a cut (program_camera.py), at
                                         # most once in this long, so that a subject running past corners does not make a cut
                                         # every frame; between, the degraded pose stays, s. [0, 60]
    seen_again_lookahead_s: float = 1.0  # and its new place is the one that sees them best now and this far ahead (the
                                         # buffered future; replacement.py looks as far), s. [0, 10]
    stand_reach_m: float = 20.0          # a planned shot's camera may stand at a level camera node this near its kept player
                                         # at the cut (stand.py), m. (0, 200]
    stand_step_s: float = 0.25           # a stand is judged at the shot's moments this far apart (and at its events), s.
                                         # [0.05, 5]
    stand_event_weight: float = 2.0      # an event's moment weighs this against 1 for the others (the kill must be seen).
                                         # (0, 100]
    stand_shown_height_min: float = 0.15  # a stand frames its kept player at least this share of the frame's height (issue
                                         # 41's median bar is 0.15), share. (0, shown_height_max]
    stand_margin: float = 0.0            # and must see at least this much better than the Toric place (stand.py), share.
                                         # [0, 1]
    first_person: bool = True            # our director may take a shot through its kept player's eyes (first_person.py)
    eyes_fov_deg: float = 73.74          # a first-person shot's vertical field of view: QuakeWorld's default fov 90 across
                                         # 4:3 (ezQuake keeps the vertical angle on wider screens), deg. (1, 170)
    eyes_seen: float = 0.5               # a planned shot goes through its kept player's eyes when from there each of its
                                         # other subjects is seen this share of its points at each of its events
                                         # (eval-match's shown fraction), share. [0, 1]
    eyes_shown_height_min: float = 0.1   # and only where each is near enough to read from there: this share of the frame's
                                         # height, by distance (first_person.py), share. [0, 1]
    follow_eyes_height_min: float = 0.15  # a discretionary FOLLOW goes through its player's eyes only where they show the
                                         # others this share of the frame's height (median), its Toric camera would meet a
                                         # wall or lose it, or it kills or dies in the buffer (first_person.py; issue 41's
                                         # median bar), share. [0, 1]
    eyes_lead_s: float = 1.0             # or, where its Toric camera would meet a wall within the shot, at some moment this
                                         # long before each event (first_person.py), s. [0, 10]
    shown_height_max: float = 0.5        # the framing band's top: a shot's camera is placed where none of its subjects fills
                                         # more of the frame's height than this, by distance (shot_builder.py): a whole body
                                         # with room around it, a long shot; closer, a medium shot cuts the body (and in this
                                         # measure, "taller than the frame"); issue 41 bars 0.6, share of frame height. (0, 1]
    follow_shown_height: float = 0.35    # a FOLLOW at the style's place frames its player this share of the frame's height
                                         # (its gaze room grows to put the camera that far: shot_builder.py); the style's
                                         # 2.5 m put it 3.9 m off, a 1.75 m player at 0.48 (real duel: 40% of program frames
                                         # had a player over 0.6), share of frame height. (0, shown_height_max]
    widen_max_fov_deg: float = 90.0     # a program pose whose player would stand taller than shown_height_max goes this wide
                                         # at most (lens_width.py; 90 deg vertical is 121 deg across 16:9; Quake players
                                         # play at 90-120 across 4:3, 74-104 vertical); the lens's own to keep it, deg. (1, 170)
    narrow_deg_s: float = 90.0           # and zooms back toward the lens's no faster than this, deg/s: half a second from the
                                         # widest, so a camera near a wall does not pump frame to frame; at 20 deg/s the wide
                                         # frames lasted and showed more far-off players (nav_test's median height
                                         # 0.138 -> 0.130). (0, 1000]
    zoom_min_fov_deg: float = 15.0       # a Toric or wide view whose framed subjects stand small zooms in, to this (lens_width.py
                                         # `zoomed_fov_deg`; on open levels players in the shot stood 0.06-0.15 of the frame
                                         # at the lens's 50), deg; the lens's own or wider to keep it. (1, 170)
    zoom_shown_height: float = 0.35      # until its tallest framed subject stands this share of the frame's height (a
                                         # FOLLOW's follow_shown_height: the style's own size for one player), share.
                                         # (0, shown_height_max]
    zoom_safe: float = 0.93              # keeping every framed subject's outline inside this share of the frame about its
                                         # centre (SMPTE ST 2046-1's action-safe area, 93%), share. (0, 1]
    zoom_deg_s: float = 30.0             # zooming in no faster than this (zooming out is at once, as the framing needs),
                                         # deg/s: 50 -> 15 degrees in a little over a second, a push-in, not a snap. (0, 1000]
    candidate_seen: float = 0.5          # a candidate's subject is shown from its camera with this share of its points seen
                                         # (eval-match's shown fraction). [0, 1]
    candidate_min_shown: float = 0.5     # a candidate is offered only when it shows this share of its subjects at the
                                         # moment it is offered (issue 41: at least half). [0, 1]
    priorities: dict[EventKind, int] = field(default_factory=lambda: {
        EventKind.UNSPECIFIED: 1, EventKind.KILL: 7, EventKind.DAMAGE: 3, EventKind.OBJECTIVE: 5,
        EventKind.CUSTOM: 4})            # the kind's default priority (a death is 7 as in HLTV), [1, 15]
    hltv: HltvSettings = field(default_factory=HltvSettings)

    def __post_init__(self) -> None:
        _check_positive_finite(self, ("plan_rate_hz", "lookahead_s", "respawn_speed_m_s", "respawn_min_jump_m",
                                      "respawn_walk_m", "engage_range_m", "join_spread_max_m", "reframe_s", "max_held_shot_s",
                                      "group_radius_m", "overview_height_m", "pull_regrow_m_s", "move_speed_max_m_s",
                                      "stand_reach_m",
                                      "stand_event_weight", "stand_shown_height_min"))
        if not (self.stand_reach_m <= 200.0 and 0.05 <= self.stand_step_s <= 5.0 and self.stand_event_weight <= 100.0
                and self.stand_shown_height_min <= self.shown_height_max and self.stand_margin <= 1.0):
            raise ValueError("MatchSettings: stand_reach_m in (0, 200] m, stand_step_s in [0.05, 5] s, stand_event_weight "
                             "in (0, 100], stand_shown_height_min in (0, shown_height_max], stand_margin in [0, 1]")
        if not 0.0 <= self.wall_hold_max_m <= 100.0:
            raise ValueError("MatchSettings: wall_hold_max_m in [0, 100] m")
        if self.move_speed_max_m_s > 1000.0 or not 0.0 <= self.move_cut_s <= 10.0:
            raise ValueError("MatchSettings: move_speed_max_m_s in (0, 1000] m/s, move_cut_s in [0, 10] s")
        if not (1.0 < self.eyes_fov_deg < 170.0 and 0.0 <= self.eyes_seen <= 1.0 and 0.0 <= self.eyes_lead_s <= 10.0
                and 0.0 <= self.eyes_shown_height_min <= 1.0 and 0.0 <= self.follow_eyes_height_min <= 1.0):
            raise ValueError("MatchSettings: eyes_fov_deg in (1, 170) deg, eyes_seen, eyes_shown_height_min and "
                             "follow_eyes_height_min in [0, 1], "
                             "eyes_lead_s in [0, 10] s")
        if self.edit_window_s > 10.0 or self.edit_lengthen_s > 10.0:
            raise ValueError("MatchSettings: edit_window_s and edit_lengthen_s in [0, 10] s")
        if self.seen_again_gap_s > 60.0 or self.seen_again_lookahead_s > 10.0:
            raise ValueError("MatchSettings: seen_again_gap_s in [0, 60] s, seen_again_lookahead_s in [0, 10] s")
        if not self.min_lead_s <= self.lead_s <= self.max_lead_s:
            raise ValueError("MatchSettings: need min_lead_s <= lead_s <= max_lead_s")
        if not 2 <= self.max_group <= 64 or not 1 <= self.samples_per_player <= 256 \
                or not 1 <= self.beat_min_priority <= 15:
            raise ValueError("MatchSettings: max_group in [2, 64], samples_per_player in [1, 256], "
                             "beat_min_priority in [1, 15]")
        if not -1.0 <= self.facing_cos <= 1.0 or not 0.0 <= self.min_visible <= 1.0 or not 0.0 <= self.pull_below <= 1.0:
            raise ValueError("MatchSettings: facing_cos in [-1, 1], min_visible and pull_below in [0, 1]")
        if not 0.0 < self.follow_shown_height <= self.shown_height_max:
            raise ValueError("MatchSettings: need 0 < follow_shown_height <= shown_height_max")
        if not 0.0 < self.shown_height_max <= 1.0 or not 0.0 <= self.candidate_seen <= 1.0 \
                or not 0.0 <= self.candidate_min_shown <= 1.0:
            raise ValueError("MatchSettings: shown_height_max in (0, 1], candidate_seen and candidate_min_shown in [0, 1]")
        if not 1.0 < self.widen_max_fov_deg < 170.0 or not 0.0 < self.narrow_deg_s <= 1000.0:
            raise ValueError("MatchSettings: widen_max_fov_deg in (1, 170) deg, narrow_deg_s in (0, 1000] deg/s")
        if not 1.0 < self.zoom_min_fov_deg < 170.0 or not 0.0 < self.zoom_shown_height <= self.shown_height_max \
                or not 0.0 < self.zoom_safe <= 1.0 or not 0.0 < self.zoom_deg_s <= 1000.0:
            raise ValueError("MatchSettings: zoom_min_fov_deg in (1, 170) deg, zoom_shown_height in (0, shown_height_max], "
                             "zoom_safe in (0, 1], zoom_deg_s in (0, 1000] deg/s")
        if not 1e3 <= self.plan_work_per_tick <= 1e9:
            raise ValueError(f"MatchSettings: plan_work_per_tick in [1e3, 1e9] camera-point pairs, got {self.plan_work_per_tick}")
        if self.max_held_shot_s > 600.0:
            raise ValueError("MatchSettings: max_held_shot_s in (0, 600] s")
        if self.pair_before_s > 30.0 or self.pair_after_s > 30.0 or self.reframe_s > 10.0:
            raise ValueError("MatchSettings: pair_before_s and pair_after_s in [0, 30] s, reframe_s in (0, 10] s")
        if not (self.replay_pre_s <= 10.0 and self.replay_post_s <= 10.0 and self.replay_after_s <= self.replay_within_s <= 30.0):
            raise ValueError("MatchSettings: replay_pre_s and replay_post_s in [0, 10] s, "
                             "replay_after_s <= replay_within_s <= 30 s")
        if set(self.priorities) != set(EventKind) or not all(1 <= p <= 15 for p in self.priorities.values()):
            raise ValueError("MatchSettings: one priority in [1, 15] per EventKind")

    @property
    def plan_interval_s(self) -> float:
        return 1.0 / self.plan_rate_hz

    @property
    def replay_length_s(self) -> float:
        """A REPLAY shot's length, s."""
        return self.replay_pre_s + self.replay_post_s

    @property
    def replay_past_s(self) -> float:
        """How far before its start a replay may reach back, s."""
        return self.replay_within_s + self.replay_pre_s

    @property
    def kept_past_s(self) -> float:
        """How much past, before the moment the rig works (the edit window's head), the buffer
        keeps, s: a replay's reach, and the edit window's length more for a replay the window
        starts early, which shows the moments before its first (edit_window.py)."""
        return self.replay_past_s + self.edit_window_s


def _check_positive_finite(settings: MatchSettings | HltvSettings, positive: tuple[str, ...]) -> None:
    """Every float field finite, >= 0 (pitches may be negative), and > 0 for the names in `positive`."""
    for f in fields(settings):
        value = getattr(settings, f.name)
        if not isinstance(value, float):
            continue
        low_ok = value > 0.0 if f.name in positive else (value >= 0.0 or "pitch" in f.name)
        if not (math.isfinite(value) and low_ok):
            raise ValueError(f"{type(settings).__name__}: {f.name} out of range, got {value}")
