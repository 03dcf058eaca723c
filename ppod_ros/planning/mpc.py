"""Model-predictive manipulation: several parts, each to its own goal pose, at once.

At each replanning step (every ``replan_period_s`` of device time, camera poses in between) the
planner chooses the plate motion itself, not a field kind:

  predict   each commanded part's asymptotic velocity (point part) or twist (rigid part, x, y and
            theta) under a candidate motion, at its tracked configuration (planning/predict.py:
            all candidates in one batched call), times the part's estimated velocity scale,
            carried over the horizon ``horizon_s``.
  cost      the distance of each predicted configuration from its waypoint (the goal, or the
            point ``max_speed_mps * horizon_s`` towards it when it is farther: a reachable goal
            for the horizon), angles weighted by ``angle_weight_m_per_rad``; parts already within
            tolerance are asked to stay (weight ``hold_weight``), within ``hold_within`` of their
            tolerances; predicted positions of two parts
            closer than their footprints plus ``clearance_m`` are penalised; a candidate that
            loses contact at any commanded part is rejected.
  search    candidates: the last motion, the plate at rest, the template fields (the sink
            centred on each goal, a rotation about a rigid part both ways, the orienting motion
            through its goal, the spin of a rigid part in place both ways, the transport the way
            a part not yet near its goal has to go; designed once at the centre and moved with
            exact transformations; the best few ranked fitted into the envelope), then Gauss-Newton
            steps on the 12 (one frequency) or 24 (two) real inputs from the best of them,
            with finite-difference Jacobians evaluated in one batched call and a trust region
            (``max_change``, relative to the typical axis scales) so a switch is a small change:
            with the generator's ramp and the feedback's predicted first error the parts follow
            the predicted path instead of being thrown.
  envelope  the chosen motion is scaled down until the generator's own checker accepts it with
            ``headroom`` under every limit (planning/envelope.py).
  switch    the new motion is sent only if it beats the current one by ``switch_gain`` (each
            switch restarts the feedback's learning).
  estimate  between replanning steps each moving part's displacement is compared with the
            predicted one: the velocity scale (friction and plant error the model does not know)
            is the least-squares ratio, smoothed (``scale_gain``), within ``scale_range``.
  finish    a part within tolerance is asked to stay; when every commanded part is within
            tolerance the plate is stopped (a plate at rest holds every part); done when all
            have stayed within tolerance for ``settle_s``.

Nothing here imports rclpy or message types.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from ppod_ros.errors import ConfigError
from ppod_ros.motion import PlateMotion, crossfade
from ppod_ros.parts import PointPart, RigidPart
from ppod_ros.planning.design import _SCALE, DEFAULT_FREQUENCY_HZ, design_field, orient_phasors
from ppod_ros.planning.envelope import PlantTolerance, fit_envelope, fit_envelope_many, uncorrected_motions
from ppod_ros.planning.predict import budgeted, predict_velocities
from ppod_ros.planning.specs import CENTRE_RADIUS_M, FieldSpec
from ppod_ros.planning.task import TaskStep


@dataclass(frozen=True)
class MpcSettings:
    """Tuning constants of the model-predictive planner (units in the names)."""

    replan_period_s: float = 0.5          # device time between replanning steps (>= 2 Hz)
    horizon_s: float = 1.0                # prediction horizon
    ramp_s: float = 0.5                   # the generator's ramp on a switch (device default_ramp_s)
    approach_per_s: float = 0.8           # waypoint: this fraction of the error per horizon second (with no
                                          # command latency; see latency_ref_s)
    latency_ref_s: float | None = 0.5     # the approach gain falls with the command latency L (frame to the
                                          # motion playing, :meth:`MultiTask.command_latency`) as
                                          # approach_per_s / (1 + L / latency_ref_s): a motion chosen on poses
                                          # L old keeps a part moving L longer, and at the full gain the
                                          # endgame oscillates (the demo's scene in the loop, 0.5 s, 20 plant
                                          # seeds: 10/20 reached in 90 s, 19/20 lowered; docs/planner.md).
                                          # None: off
    latency_smoothing: float = 0.3        # weight of each reported latency in its running mean
    latency_from_parts: int = 2           # ... the gain lowered only when at least this many parts are
                                          # commanded: one bracket under 0.3 s of latency came out 38/40 with
                                          # it lowered against 40/40 (a slower last turn let it stick), three
                                          # parts 36/40 against 33/40 (benchmark seeds 0 and 1; docs/planner.md)
    frequency_hz: float = DEFAULT_FREQUENCY_HZ  # of the searched motions
    harmonics: int = 1                    # 1: 12 real inputs; 2: 24 (the Gauss-Newton search's)
    two_harmonics_from_parts: int = 2     # ... and 2 whenever at least this many parts are commanded (0: never):
                                          # a one-frequency field is near linear, 6 coefficients for three
                                          # parts' 6 velocities and more; two frequencies reach more fields
                                          # (bracket and washer, benchmark scenes 0-19: 20/20 against 18/20;
                                          # three parts 20/20 against 19/20; docs/planner.md, "Measured")
    headroom: float = 0.15                # fraction under every device limit
    plant_tolerance: PlantTolerance | None = PlantTolerance()  # actuator errors whose corrected tables must
                                          # pass the checker too (planning/envelope.py); None: nominal only
    max_speed_mps: float = 0.015          # waypoint distance per horizon second (0.008 before the spin and
                                          # transport templates: one bracket median 16 s against 9 s)
    max_turn_radps: float = 0.5           # angular waypoint per horizon second
    angle_weight_m_per_rad: float = 0.03  # an angle error of 1 rad costs as much as 30 mm
    angle_from_m: float = 0.01            # ... within this distance of the goal; farther, the angle weight
                                          # falls as this distance over the part's (transport first: a sink
                                          # that carries the bracket home spins it, the turn comes near the end)
    hold_weight: float = 3.0              # parts within tolerance: weight of staying put
    hold_release: float = 1.5             # ... until out by this many tolerances (hysteresis)
    hold_within: float | None = 0.6       # a held part within tolerance is asked to stay where it is up to
                                          # this fraction of its tolerances, and back to it from beyond (the
                                          # stop needs every part within stop_within). None: where it is, which
                                          # let held parts creep out by the motions that served the others (a
                                          # washer held from 1.3 mm was 1.98 mm off when the plate stopped,
                                          # 2.09 mm by ground truth: the demo's tolerance 2 mm)
    region_radius_m: float = 0.065        # predicted positions beyond this (and beyond the part's own) rule
                                          # a candidate out: parts are never driven off the working disc
    clearance_m: float = 0.002            # predicted footprints closer than this are penalised
    collision_weight: float = 5.0
    gauss_newton_steps: int = 2
    line_search: str = "first"            # "first": the first of the step lengths 1, 1/2, 1/4 that lowers the
                                          # cost, each fitted and solved only if the longer ones did not; "best":
                                          # all three fitted and solved, the cheapest taken. Benchmark scenes,
                                          # seeds 0 and 1, side by side: four parts 23/40 against 22/40, three
                                          # 37/40 against 38/40, searched steps' CPU median 4-10 % lower
    fd_step: float = 0.03                 # finite-difference step, relative to the axis scales
    local_probes: bool = True             # a point part's Jacobian columns along the plate's rotation inputs
                                          # from its translation probes (the chain rule: a point part feels the
                                          # plate only at its own point, a = p'' + alpha x r): 13 of 25 probe
                                          # motions solved per point part over two harmonics. Four parts'
                                          # searched steps 8 % less CPU on the same states (three: 6 %),
                                          # outcomes within the noise (docs/planner.md, "Local probes")
    max_change: float = 0.6               # trust region per step, relative to the axis scales
    min_amplitude: float = 0.8            # searched motions keep at least this fraction of the template
                                          # sink's amplitude (relative to the axis scales): weak motions
                                          # let parts of unknown, higher friction stick
    min_dwell_s: float = 1.0              # at least this long between switches (except to stop the plate):
                                          # each new motion starts with the feedback's first error
    near_m: float = 0.004                 # every moving part this close: the endgame
    near_dwell_s: float = 1.0             # ... where switches may wait longer (2 s measured slower: one bracket
                                          # median 17.0 s against 14.2 s on 10 benchmark scenes; 0.5 s worse)
    switch_gain: float = 0.2              # a new motion must lower the cost by this fraction (or grow the
                                          # progress over the plate at rest by it: MultiTask._better)
    fitted_candidates: int = 3            # the best this many candidates are ranked fitted into the envelope
    ramp_midpoint: str = "estimate"       # the ramp of a switch predicted with the model at the crossfade's
                                          # midpoint (the plate motion the generator plays half-way, solved) and
                                          # integrated by Simpson's rule: "estimate": the switch's prediction (the
                                          # segment the velocity scales are estimated from, ``last_prediction``);
                                          # "plan": the ranked candidates, the refined motion and the motion
                                          # chosen costed so too; "off": the velocities crossfaded linearly. A
                                          # field is far from linear in the motion: half-way from a turn to a
                                          # weak motion the model moves a bracket at 9.1 mm/s, faster than
                                          # either motion does (6.1 and 3.5 mm/s) and another way
    scale_gain: float = 0.6               # smoothing of the velocity-scale estimate per step
    scale_range: tuple[float, float] = (0.4, 4.0)
    min_predicted_m: float = 3e-4         # predicted displacements shorter than this teach nothing (15 times
                                          # the tracker's noise; at 1 mm a bracket stuck 1.2 mm from its goal
                                          # under a weak motion kept its scale, and the plan, for 55 s)
    integral_per_s: float = 0.3           # integral action on a part's position near its goal: the point the
                                          # planner aims the part at moves by this fraction of the part's
                                          # position error per second (0: off). Under the weak fields near a
                                          # goal, the model's friction and the plant error shift the field's
                                          # zero by more than a 1 mm tolerance, and a velocity scale cannot move
                                          # a zero: one washer alone to 1 mm (the demo's scene, the loop, 20
                                          # plant seeds) reached in 8 of 20 without it, 20 of 20 with it
    integral_within_m: float = 0.005      # ... only while the part is this near its goal
    integral_after_s: float = 5.0         # ... and once it has been so near for this long in all (a part that
                                          # settles at once is left as it was)
    integral_max_m: float = 0.004         # ... the aim at most this far from the goal
    integral_parts: str = "point"         # ... for "point" parts or "all" commanded parts
    integral_max_parts: int = 1           # ... only while at most this many parts are commanded. With several,
                                          # the motions that serve the others move a part too, and its error is
                                          # not a zero's shift: three parts, loop seeds 1-3, 56/60 and 55/60
                                          # against 58/60 without (point parts; all parts); one bracket worst
                                          # 22.5 / 15.5 s against 16.4 / 15.5 s (docs/planner.md)
    stall_s: float = 4.0                  # no 10 % progress over this long: focus on one part ("alternate
    focus_s: float = 3.0                  # motions") for this long, the others' weights times
    focus_others: float = 0.2             # this (a linear field cannot serve every part at once)
    focus_held: float = 0.2               # ... and the held parts' weights times this while the focused part is
                                          # within near_m of its goal position: the endgame, where every motion
                                          # that turns a bracket a few degrees moves the held washers (the spin
                                          # about it 0.5 mm per degree) and the weak motions that keep them let
                                          # it stick (the demo: 5-8 deg off for 60 s). The demo's scene in the
                                          # loop, 20 seeds: worst 45.2 -> 41.6 s; three parts, scenes 0-19:
                                          # 19/20 both, median time to goal 37.2 -> 35.8 s (1.0: off)
    stop_within: float = 0.6              # the plate stops when every part is within this fraction of its
                                          # tolerances (tracker noise must not flip a part back out)
    rest_average_after_s: float | None = 0.2  # the plate at rest holds every part: from this long after its ramp
                                          # down (the tracker's latency), a commanded part's pose is the mean of
                                          # the frames since, so the tracker's noise cannot flip a part at its
                                          # tolerance in and out (a bracket 0.95 mm from its goal, tolerance 1 mm,
                                          # read 0.86-1.08 mm at rest for 2.5 s, never held for settle_s, and the
                                          # plate restarted four times: benchmark seed 1 scene 8). None: off
    hold_at_rest: bool = True             # the plate at rest and every part within tolerance: no new motion
                                          # while they settle (settle_s), the plate at rest holds them ...
    rest_hold_within: float = 0.9         # ... within this fraction of its tolerances, a margin for the
                                          # tracker's error (at 1.0 a demo run ended with a washer held at 1.99
                                          # mm by the tracker, 2.03 mm by ground truth, tolerance 2 mm; the
                                          # benchmark's scenes: one bracket and three parts alike either way)
    done_within: float = 1.0              # done only with every part within this fraction of its tolerances
                                          # (below 1: a part within tolerance but beyond it is not stopped for
                                          # and is moved again from rest, a margin for the tracker's error).
                                          # 0.9 in the ROS-free loop: parts ending beyond 0.9 of a tolerance
                                          # by ground truth 0 of 291 against 13; three parts 77/80 both, times
                                          # +1.2 %; the demo's scene 20/20, two of 20 runs 11 and 22 s slower;
                                          # one bracket unchanged but one scene (docs/planner.md). 1: off
    stop_ahead: bool = True               # judge the stop where the ramp down leaves the parts, not where they
                                          # are (a bracket stopped 0.4 mm from its goal was carried 2.1 mm and
                                          # 2.7 deg past it by the ramp down, and took 6 s more to come back)
    stop_on_way: bool = True              # rank a motion also by stopping on its way: if the ramp down started at
                                          # a frame within the horizon would leave every commanded part within
                                          # stop_within of its tolerances (the stop ahead's own judgement), its
                                          # cost is at most that landing's distance from the goals (one bracket,
                                          # seeds 0-3, 80 scenes: 3 over 15 s against 6, 5.6 % less time in all;
                                          # three and four parts, the demo's scene: within the chaos; docs/planner.md)
    stop_on_way_frames: int = 2           # ... landing so for this many frames in a row (the stop is judged per
                                          # frame; 1: a spin promised a finish it passed through, seed 1 scene 7
                                          # 8.9 -> 19.6 s)
    stop_on_way_playing_frames: int = 1   # ... for the motion playing (its prediction learned under it, its ramp over)
    stop_on_way_step_s: float = 0.1       # ... frames this far apart (the camera's)
    scale_from_turn: bool = False         # a part with a goal angle: its velocity scale is learned from its
                                          # turn (at its footprint's radius) as well as its translation (on:
                                          # one bracket 20/20 but worst 28.7 s, three parts 18/20; off: 19/20,
                                          # worst 17.4 s, 19/20 in the same week: docs/planner.md); only with
                                          # turn_scale off
    settle_s: float = 0.5                 # within tolerance for this long: reached
    within_fraction: float = 1.0          # within tolerance, for the planner: within this fraction of the
                                          # tolerances, a margin for the tracker's error (the demo's washer
                                          # was 1.98 mm from its goal by the tracker, 2.09 mm by ground truth,
                                          # tolerance 2 mm). 0.9 measured worse: three parts 7/10 against
                                          # 9/10 (benchmark scenes 0-9, with hold_within 0.6), as the ramp
                                          # down leaves parts at 0.75-0.95 of their tolerances and the
                                          # endgame that follows is slow (docs/planner.md)
    lost_after_s: float = 6.0             # a commanded part unseen this long: failed (touching parts
                                          # are lost by the tracker for a while)
    templates: tuple[str, ...] = ("sink", "rotation", "orient", "spin", "transport", "pivot")  # TEMPLATES
                                          # tried per goal (with "line" too, and without the spin, 2 of 8
                                          # benchmark scenes of 3 parts against 5 of 8: the 1 s horizon takes its
                                          # fast gains for one part at the others' cost); "pivot" offers
                                          # candidates only while a part is pivoted (pivot_from_rad)
    pair_lines: bool = False              # the line sink through every two goals whose parts are near them
                                          # (4 of 8 against 5 of 8)
    swap_from_rad: float = 1.0            # two unfinished parts whose segment has to turn at least this
                                          # much to lie as their goals do (a swap: 180 deg): the rotation
                                          # about the fixed point of that rigid motion, both ways, is a
                                          # candidate (pair_rotation; no sink or transport turns the segment
                                          # between two parts; 0: off). Benchmark scenes, seeds 0 and 1:
                                          # four parts 29/40 against 19/40 (off), three 39/40 against
                                          # 37/40; 0.6 and 2.0 rad: three parts 37/40 and 16/20 (seed 0)
    unlearned_motions: int = 0            # the accelerometer feedback plays a session's first motions with
                                          # the plant it has not learned yet (docs/feedback.md: 12-18 % off,
                                          # then 3.5 %): they are predicted at the mean velocity over the
                                          # plant tolerance's draws of the uncorrected plant (0: never)
    feedback_first_estimate_s: float = 1.0  # ... until its first estimate after the switch, and from there
    feedback_decay_s: float = 1.0         # the error decays with this time constant (ActuatorPlantError)
    first_error_weight: float = 0.0       # an unlearned motion's candidates also cost the spread (rms, m) of
                                          # each part's predicted displacement over those draws, times this:
                                          # a sink's velocity off its centre varies 0.3-3x over them, a
                                          # transport's +-25 %
    friction_prior: tuple[float, float] = (0.67, 1.5)  # a part whose velocity scale is not estimated yet
                                          # (no motion has moved it): its friction is this range times the
                                          # model's (0.2-0.45 about 0.3), and the candidates also cost the
                                          # spread of its predicted displacement over that range (a bracket
                                          # of friction 0.42 moved at 0.54 of the model, one of 0.22 at 1.0)
    gentle_speed_mps: float = 0.0         # start gently: a motion from rest while a commanded part's velocity
                                          # scale is not estimated yet is scaled down (``gentle_amplitudes``,
                                          # the largest that fits) until no such part is predicted faster than
                                          # this, so its unknown friction cannot throw it far (0: off)
    gentle_amplitudes: tuple[float, ...] = (1.0, 0.9, 0.8, 0.7, 0.6, 0.5)
    teach_amplitude: float = 1.0          # the task's first motion (from rest) plays at this fraction of its
                                          # amplitude for teach_s, then at full amplitude: the accelerometer
                                          # feedback's plant learner, taught by the quiet copy (the same
                                          # current directions), starts the full motion learned instead of
                                          # 15-25 % off (docs/planner.md, "Teaching the feedback first").
                                          # 1.0: off. At 0.4 the first two motions' switch deviation fell
                                          # 3-4 times (one bracket 5.31 -> 1.75 mm), but the later motions'
                                          # did not and one bracket took 21 % longer in all on seed 1
    teach_s: float = 1.5                  # ... long enough for the feedback's first estimate (about 1 s)
    friction_grid: tuple[float, ...] = (0.67, 0.8, 1.0, 1.25, 1.5)  # a gentle start teaches the part's friction
                                          # (these times the model's), not a velocity scale: friction slows a
                                          # weak motion more than a strong one (a bracket of friction 0.4 moved at
                                          # 0.4 of the model under a gentle start and 0.9 under the next motion,
                                          # which its scale 0.4 then planned at 28 mm/s)
    template_sink_gain_per_s: float = 0.3
    template_speed_mps: float = 0.02      # the transport design (point part; a bracket about 15 mm/s)
    template_turn_radps: float = 0.3
    strong_turn_from_rad: float = 0.26    # the transport is not tried for a part within near_m of its goal
                                          # and this angle (15 deg): in the demo (2 mm / 3 deg tolerances) it threw
                                          # the parts near their goals about for 60 s (the spin is needed
                                          # there for the bracket's last degrees: without it 5 of 10
                                          # three-part scenes against 7 of 10)
    spin_angular_radps2: float = 400.0    # the spin template: the plate turning about z through the part
    spin_vertical_mps2: float = 4.0       # with a vertical acceleration in phase (fitted into the envelope):
                                          # normal force high while the plate turns one way, low the other,
                                          # so a rigid part turns in place (bracket 0.35 rad/s in the model,
                                          # the rotation design 0.045 rad/s)
    turn_scale: bool = True               # a part with a goal angle has velocity scales for its turn, learned
                                          # from its turn alone (the translation's from its translation alone):
                                          # one for every motion (kept in ``scale_range``) and one for the motion
                                          # playing (in ``turn_scale_range``). Friction slows a turn and a
                                          # translation differently, and one motion's turn more than another's:
                                          # the bracket of benchmark scene 15 turned at 0.14 of the model under
                                          # one motion, 0.9 under the next (the translation scale said 0.4) and
                                          # overshot its goal angle by 17 deg; one turn scale for every motion
                                          # kept a motion turning at 0.2 of the model for 15-20 s (scenes 2, 15)
    turn_scale_by_name: bool = True       # a part's turn scale is also kept per motion name (a template
                                          # moved to the part, "spin-@0", or the refined "mpc"): a motion
                                          # not playing is ranked with its name's, where one was learned (a
                                          # bracket of friction 0.44 turned at 7 deg/s under refined motions,
                                          # 11-18 deg/s under the spin). Benchmark scenes, seeds 0 and 1, side
                                          # by side: one bracket worst 15.8 / 16.7 s against 17.2 / 17.5 s,
                                          # three parts 39/40 against 37/40, four 23/40 either way
    scale_by_name: str = "off"            # a part's translation scale is also kept per motion name, as the
                                          # turn's (``turn_scale_by_name``): a motion is ranked with its
                                          # name's where one was learned, the part's otherwise; "rigid": for
                                          # rigid parts, "all": for every part, "off"
    min_predicted_turn_rad: float = 0.0175  # predicted turns smaller than this (1 deg, 10 times the tracker's
                                          # angle noise) teach the turn scales nothing
    weak_turn_pool_gain: float = 0.1      # segments whose predicted turn is under min_predicted_turn_rad are
                                          # pooled per motion name until their predicted turns reach it together
                                          # (root sum of squares); the pool's least-squares ratio then moves the
                                          # turn scales at this fraction of scale_gain (0: weak turns teach
                                          # nothing). A bracket 3-7 deg off its goal angle under refined motions
                                          # predicted to turn it 0.6-0.9 deg a segment kept a turn scale of 1.9-2.9
                                          # learned under strong turns and did not turn for 20-35 s. The demo's
                                          # scene in the loop (20 plant seeds), 0 / 0.1 / 0.25: worst 50.5 / 36.1 /
                                          # 24.5 s, sum 323 / 277 / 256 s; three parts, seeds 1-3 (not tuned on):
                                          # 56 / 58 / 56 of 60, sum 1687 / 1664 / 1716 s (docs/planner.md)
    turn_scale_range: tuple[float, float] = (0.1, 4.0)  # the motion playing: a weak turn whose contacts
                                          # stick turns at 0-0.2 of the model
    probe_max_steps_per_period: int = 200  # the solver's budget for the Gauss-Newton probes and line-search
    probe_max_periods: int = 12           # trials (the candidates keep PLANNER_SOLVER's 1500 and 40): a row
                                          # that needs more is out (a probe: no Jacobian column; a trial: not
                                          # taken). Rows that converge within it are bit for bit the same;
                                          # the stick-slip rows of the bracket that hit 1500 steps cost 10-130 ms
                                          # each and made the replanning time's tail (docs/planner.md). 0: no budget
    budget_fitted: bool = False           # the best candidates fitted into the envelope on that budget too
    gave_up_max_steps_per_period: int = 0  # an option, off (measured with 800, 12, 0.01): a fitted candidate
    gave_up_max_periods: int = 0          # (template kind and goal) the solver gave up on at PLANNER_SOLVER's
    gave_up_near_m: float = 0.01          # caps is solved on this budget while each part it gave up at is
                                          # within gave_up_near_m and hold_gave_up_rad of its pose there (not
                                          # re-recorded on the budget; converged or contact lost: forgotten).
                                          # Four parts: replanning thread CPU p95 158 -> 145 ms, 4/10 both; three
                                          # parts 19/20 -> 18/20 (six scenes changed); at 200 or 400 steps three-
                                          # part scene 0 timed out (docs/planner.md). 0 and 0: off
    rest_dwell_s: float | None = 0.5     # from the plate at rest (a part out again after the stop: the ramp down
                                          # carried a bracket stopped 0.86 mm from its goal back to 1.2 mm), the
                                          # next motion may start this long after the stop (the ramp's end)
                                          # instead of min_dwell_s (None: min_dwell_s)
    pivot_from_rad: float = 0.6           # a rigid part this far from its goal angle (and the pivot within
                                          # region_radius_m of the centre) is turned about the pivot: the fixed
                                          # point of the rigid motion from its pose to its goal pose. Its waypoint
                                          # is its pose turned about the pivot (the turn and the translation at
                                          # once), its angle weighed in full at any distance, and the spin moved
                                          # to the pivot is a template ("pivot"). In the model the spin about a
                                          # point 10 mm from the bracket turns it at 0.9-1.0 of the spin in place
                                          # and carries it at 4.7 mm/s along the circle (a rigid turn about that
                                          # point); the slow scenes carried the bracket home first (3 s, no
                                          # turn) and then turned it 115-170 deg at 10-16 deg/s. One bracket,
                                          # benchmark scenes 0-39: 40/40 both, median 7.5 -> 7.3 s, 90th
                                          # percentile 12.8 -> 12.6 s, over 15 s 2 -> 1 (docs/planner.md). 0: off
    pivot_min_scale: float = 0.75         # ... once the part's (translation) velocity scale is estimated and while
                                          # it is at least this: a bracket of high friction (0.36-0.44: scale
                                          # 0.5-0.73 after 1 s, 0.77-0.96 at 0.22-0.30) turned about its pivot
                                          # at 0.2 of the model, 5 deg/s (ungated, 1 rad: scene 16 16.2 -> 28.9 s,
                                          # 7 of 40 over 15 s); gated from the start (unestimated scale 1): 4 of 40
    hold_gave_up_m: float = 0.005         # the motion playing, when the solver gives up on it ("not converged"
    hold_gave_up_rad: float = 0.17        # under PLANNER_SOLVER's caps, not contact lost) at a pose within this
                                          # distance and angle (10 deg) of every commanded part's pose where it
                                          # last converged: predicted with that last prediction, not ruled out
                                          # (an inf cost forced a switch away from a motion that works; 0: off)

    def __post_init__(self):
        for name in ("replan_period_s", "horizon_s", "frequency_hz", "max_speed_mps", "max_turn_radps",
                     "fd_step", "max_change", "settle_s", "lost_after_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ConfigError(f"{name}: must be > 0, got {v!r}")
        if self.replan_period_s > 0.5:
            raise ConfigError(f"replan_period_s: must be <= 0.5 s (replanning at >= 2 Hz), got {self.replan_period_s}")
        unknown = [k for k in self.templates if k not in TEMPLATES]
        if unknown:
            raise ConfigError(f"templates: unknown kind {unknown[0]!r}; expected some of {', '.join(TEMPLATES)}")
        if self.scale_by_name not in ("off", "rigid", "all"):
            raise ConfigError(f"scale_by_name: expected 'off', 'rigid' or 'all', got {self.scale_by_name!r}")
        if self.ramp_midpoint not in ("off", "estimate", "plan"):
            raise ConfigError(f"ramp_midpoint: expected 'off', 'estimate' or 'plan', got {self.ramp_midpoint!r}")
        if self.latency_ref_s is not None and not (isinstance(self.latency_ref_s, (int, float))
                                                   and math.isfinite(self.latency_ref_s) and self.latency_ref_s > 0):
            raise ConfigError(f"latency_ref_s: must be > 0 s (None: off), got {self.latency_ref_s!r}")
        if not (isinstance(self.latency_from_parts, int) and self.latency_from_parts >= 1):
            raise ConfigError(f"latency_from_parts: expected an integer >= 1, got {self.latency_from_parts!r}")
        v = self.latency_smoothing
        if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 < v <= 1):
            raise ConfigError(f"latency_smoothing: expected a weight 0..1, got {v!r}")
        if not isinstance(self.local_probes, bool):
            raise ConfigError(f"local_probes: expected true or false, got {self.local_probes!r}")
        v = self.teach_amplitude
        if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 < v <= 1):
            raise ConfigError(f"teach_amplitude: expected a fraction in (0, 1] (1: off), got {v!r}")
        v = self.teach_s
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
            raise ConfigError(f"teach_s: expected a time >= 0 s, got {v!r}")
        if self.line_search not in ("best", "first"):
            raise ConfigError(f"line_search: expected 'best' or 'first', got {self.line_search!r}")
        if self.harmonics not in (1, 2):
            raise ConfigError(f"harmonics: expected 1 or 2, got {self.harmonics!r}")
        if not (isinstance(self.two_harmonics_from_parts, int) and self.two_harmonics_from_parts >= 0):
            raise ConfigError(f"two_harmonics_from_parts: expected an integer >= 0 (0: never), "
                              f"got {self.two_harmonics_from_parts!r}")
        if not 0.0 <= self.headroom < 0.5:
            raise ConfigError(f"headroom: expected 0..0.5 (fraction), got {self.headroom!r}")
        for name in ("probe_max_steps_per_period", "probe_max_periods", "gave_up_max_steps_per_period",
                     "gave_up_max_periods"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 0):
                raise ConfigError(f"{name}: expected an integer >= 0 (0: no budget), got {v!r}")
        for name in ("integral_per_s", "integral_within_m", "integral_after_s", "integral_max_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"{name}: must be >= 0, got {v!r}")
        if not (isinstance(self.integral_max_parts, int) and self.integral_max_parts >= 0):
            raise ConfigError(f"integral_max_parts: expected an integer >= 0, got {self.integral_max_parts!r}")
        if self.integral_parts not in ("all", "point"):
            raise ConfigError(f"integral_parts: expected 'all' or 'point', got {self.integral_parts!r}")
        v = self.weak_turn_pool_gain
        if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 <= v * self.scale_gain <= 1):
            raise ConfigError(f"weak_turn_pool_gain: expected 0..1/scale_gain (0: off), got {v!r}")
        for name in ("hold_gave_up_m", "hold_gave_up_rad", "gave_up_near_m", "swap_from_rad"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"{name}: must be >= 0 (0: off), got {v!r}")
        v = self.focus_held
        if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 <= v <= 1):
            raise ConfigError(f"focus_held: expected a factor 0..1 (1: off), got {v!r}")
        for name in ("within_fraction", "rest_hold_within", "done_within"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 < v <= 1):
                raise ConfigError(f"{name}: expected a fraction 0..1 of the tolerances, got {v!r}")
        v = self.hold_within
        if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v) and 0 <= v <= 1):
            raise ConfigError(f"hold_within: expected a fraction 0..1 of the tolerances or None, got {v!r}")
        v = self.rest_average_after_s
        if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
            raise ConfigError(f"rest_average_after_s: must be >= 0 s or None (off), got {v!r}")
        v = self.rest_dwell_s
        if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
            raise ConfigError(f"rest_dwell_s: must be >= 0 s or None (min_dwell_s), got {v!r}")
        if not isinstance(self.stop_on_way, bool):
            raise ConfigError(f"stop_on_way: expected true or false, got {self.stop_on_way!r}")
        n_frames = round(self.horizon_s / self.stop_on_way_step_s) if (
            isinstance(self.stop_on_way_step_s, (int, float)) and math.isfinite(self.stop_on_way_step_s)
            and self.stop_on_way_step_s > 0) else 0
        if not 1 <= n_frames <= 1000:
            raise ConfigError(f"stop_on_way_step_s: expected a frame interval > 0 s within the horizon "
                              f"({self.horizon_s} s), got {self.stop_on_way_step_s!r}")
        for name in ("stop_on_way_frames", "stop_on_way_playing_frames"):
            v = getattr(self, name)
            if not (isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= n_frames):
                raise ConfigError(f"{name}: expected an integer 1..{n_frames} (frames within the horizon), got {v!r}")


@dataclass(frozen=True)
class PartGoal:
    """One commanded part: its row in the poses, goal (x, y in m; theta in rad or None) and tolerances."""

    index: int
    x_m: float
    y_m: float
    theta_rad: float | None = None
    position_tol_m: float = 1e-3
    angle_tol_rad: float = math.radians(2.0)

    def within(self, position_m: float, angle_rad: float | None, fraction: float = 1.0) -> bool:
        """Whether a part ``position_m`` from this goal and ``angle_rad`` off its angle (None: position
        only) is within ``fraction`` of the tolerances (NaN: not within)."""
        return position_m <= fraction * self.position_tol_m and (
            angle_rad is None or abs(angle_rad) <= fraction * self.angle_tol_rad)


@dataclass(frozen=True)
class PartStatus:
    index: int
    position_error_m: float
    angle_error_rad: float | None
    within: bool
    reached: bool
    time_to_goal_s: float | None
    velocity_scale: float


@dataclass(frozen=True)
class MultiStep(TaskStep):
    """What :meth:`MultiTask.step` returns: a TaskStep (``position_error_m`` the largest over the
    goals, ``angle_error_rad`` the largest over the oriented goals), plus one status per goal."""

    parts: tuple[PartStatus, ...] = ()
    plan_ms: float = 0.0                # wall time of this step's planning (0 between replanning steps)


def _wrap(a, period: float = 2 * math.pi):
    return (np.asarray(a) + period / 2) % period - period / 2


def _poses_near(poses: np.ndarray, ref: np.ndarray, oriented: np.ndarray, max_m: float, max_rad: float) -> bool:
    """Every row of ``poses`` (n, 3) within ``max_m`` of ``ref``'s position and, where ``oriented``,
    within ``max_rad`` of its angle; a NaN (unseen) is never near."""
    d = np.nan_to_num(np.hypot(*(poses[:, :2] - ref[:, :2]).T), nan=np.inf)
    turn = np.where(oriented, np.nan_to_num(np.abs(_wrap(poses[:, 2] - ref[:, 2])), nan=np.inf), 0.0)
    return bool(np.all(d <= max_m) and np.all(turn <= max_rad))


@lru_cache(maxsize=64)
def _pairs(n: int, G: int) -> tuple[np.ndarray, np.ndarray]:
    """Every pair (a, b) of n parts with a < G and b > a, in the order of the double loop over a, then
    b (read-only index arrays)."""
    ia, ib = np.triu_indices(n, 1)
    first = ia < G
    ia, ib = ia[first], ib[first]
    ia.flags.writeable = ib.flags.writeable = False
    return ia, ib


def part_radius_m(part: PointPart | RigidPart) -> float:
    """Radius of the part's footprint about its pose point (3 mm when none is given)."""
    fp = getattr(part, "footprint", None)
    if isinstance(part, RigidPart):
        return float(np.max(np.hypot(*part.outline().T)))
    if fp is None:
        return 0.003
    return float(fp.size[0]) if fp.kind == "disk" else float(np.max(np.hypot(*fp.outline().T)))


def _symmetry(part) -> float:
    fp = getattr(part, "footprint", None)
    s = fp.symmetry_rad if fp is not None else 2 * math.pi
    return s if s > 0 else 2 * math.pi


def check_goals(parts: Sequence[PointPart | RigidPart], goals: Sequence[PartGoal], *,
                clearance_m: float = 0.002) -> None:
    """ConfigError with the reason for goals out of the working region, repeated, or colliding."""
    if not goals:
        raise ConfigError("goals: expected at least one (part, goal pose) pair")
    seen = set()
    for g in goals:
        if not 0 <= g.index < len(parts):
            raise ConfigError(f"goals: part index {g.index} outside 0..{len(parts) - 1}")
        if g.index in seen:
            raise ConfigError(f"goals: part {g.index} is given two goals")
        seen.add(g.index)
        vals = (g.x_m, g.y_m) + (() if g.theta_rad is None else (g.theta_rad,))
        if not all(math.isfinite(v) for v in vals):
            raise ConfigError(f"goals: part {g.index}: goal must be finite, got {vals}")
        r = math.hypot(g.x_m, g.y_m)
        if r + part_radius_m(parts[g.index]) > CENTRE_RADIUS_M + 0.005:
            raise ConfigError(f"goals: part {g.index}: ({g.x_m:g}, {g.y_m:g}) m is outside the working region "
                              f"(its footprint must fit within {CENTRE_RADIUS_M + 0.005:g} m of the centre)")
        for name, v in (("position_tol_m", g.position_tol_m), ("angle_tol_rad", g.angle_tol_rad)):
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"goals: part {g.index}: {name} must be > 0, got {v!r}")
    for a in range(len(goals)):
        for b in range(a + 1, len(goals)):
            ga, gb = goals[a], goals[b]
            d = math.hypot(ga.x_m - gb.x_m, ga.y_m - gb.y_m)
            need = part_radius_m(parts[ga.index]) + part_radius_m(parts[gb.index]) + clearance_m
            if d < need:
                raise ConfigError(f"goals: parts {ga.index} and {gb.index} would collide at their goals "
                                  f"({1e3 * d:.1f} mm apart, their footprints need {1e3 * need:.1f} mm)")


# ---------------------------------------------------------------------------------- parametrisation
def _to_vector(motion: PlateMotion, harmonics: int) -> np.ndarray:
    """Real inputs (12 per harmonic, no gauge fixing: the trust region keeps steps small)."""
    table = motion.phasor_table(harmonics)[:harmonics] / _SCALE
    z = table.reshape(-1)
    return np.concatenate([z.real, z.imag])


def _to_motion(v: np.ndarray, frequency_hz: float, harmonics: int, name: str = "mpc") -> PlateMotion:
    n = 6 * harmonics
    table = ((v[:n] + 1j * v[n:]).reshape(harmonics, 6)) * _SCALE
    return PlateMotion.from_phasors(frequency_hz, np.arange(1, harmonics + 1), table, name=name)


# The designs the templates are made from: each designed once at the plate centre and moved
# with exact rotations and shifts (a rigid plate; gravity along z; isotropic friction).
BASE_KINDS: dict[str, Callable[[MpcSettings], FieldSpec]] = {
    "sink": lambda s: FieldSpec.from_request("sink", [0.0, 0.0, s.template_sink_gain_per_s]),
    "rotation": lambda s: FieldSpec.from_request("rotation", [0.0, 0.0, s.template_turn_radps]),
    "transport": lambda s: FieldSpec.from_request("transport", [s.template_speed_mps, 0.0]),
    "line_sink": lambda s: FieldSpec.from_request("line_sink", [0.0, 0.0, 0.0, s.template_sink_gain_per_s]),
}


def progress_bit(name: str, position_error_m: float, angle_error_rad: float | None, within: bool) -> str:
    """One part in a progress line ("track 4 36.1 mm +51.6 deg", " ok" once within tolerance; no
    angle for a position-only goal): the planner's texts and ``ppod demo``'s, which names parts its
    own way, share it."""
    b = f"{name} {1e3 * position_error_m:.1f} mm"
    if angle_error_rad is not None:
        b += f" {math.degrees(angle_error_rad):+.1f} deg"
    return b + (" ok" if within else "")


def base_design(kind: str, device, settings: MpcSettings | None = None) -> PlateMotion:
    """The template ``kind`` (BASE_KINDS) designed at the plate centre (cached by design_field: call
    it once at start-up, e.g. when a node configures, so the first replanning step does not pay
    the design, about a second each)."""
    try:
        spec = BASE_KINDS[kind](settings or MpcSettings())
    except KeyError:
        raise ConfigError(f"kind: expected one of {', '.join(BASE_KINDS)}, got {kind!r}") from None
    return design_field(spec, device=device).motion


def moved(base: PlateMotion, x0: float, y0: float, *, angle_rad: float = 0.0, mirror: bool = False,
          name: str = "") -> PlateMotion:
    """``base`` (harmonic 1, designed about the centre), mirrored in the x-z plane if asked (y -> -y:
    a_y, alpha_x and alpha_z change sign; every field is mirrored, a rotation turns the other way),
    turned by ``angle_rad`` about z, then moved to (x0, y0): the in-plane vectors (a_x, a_y) and
    (alpha_x, alpha_y) rotate, and the acceleration at r is the base's at r - r0 (a rigid plate:
    a0 - alpha x r0). A sign change is no reversal: -X is X half a period later, the same field."""
    X = base.phasor_table(1).copy()
    if mirror:
        X[:, [1, 3, 5]] *= -1.0
    c, s_ = math.cos(angle_rad), math.sin(angle_rad)
    for i, j in ((0, 1), (3, 4)):
        X[:, i], X[:, j] = c * X[:, i] - s_ * X[:, j], s_ * X[:, i] + c * X[:, j]
    X[:, 0] += X[:, 5] * y0
    X[:, 1] -= X[:, 5] * x0
    X[:, 2] += X[:, 4] * x0 - X[:, 3] * y0
    return PlateMotion.from_phasors(base.frequency_hz, [1], X, name=name or base.name)


# The template fields, by kind: one table (an unknown kind raises). Each builds a motion from
# (planner, goal, pose) the list of its motions, empty where it does not apply.
def _template_sink(planner: MultiTask, goal: PartGoal, pose: np.ndarray) -> list[PlateMotion]:
    return [moved(planner._base("sink"), goal.x_m, goal.y_m, name=f"sink@{goal.index}")]


def _heading(goal: PartGoal, pose: np.ndarray) -> float | None:
    d = (goal.x_m - float(pose[0]), goal.y_m - float(pose[1]))
    return math.atan2(d[1], d[0]) if math.hypot(*d) > goal.position_tol_m else None


def _template_transport(planner: MultiTask, goal: PartGoal, pose: np.ndarray) -> list[PlateMotion]:
    """Every part carried the way this part has to go (a uniform field)."""
    heading = _heading(goal, pose)
    if heading is None:
        return []
    return [moved(planner._base("transport"), 0.0, 0.0, angle_rad=heading, name=f"carry@{goal.index}")]


def _template_line(planner: MultiTask, goal: PartGoal, pose: np.ndarray) -> list[PlateMotion]:
    """A line sink through the goal, across the way to it: the part is driven straight at the line,
    and parts on the line stay."""
    heading = _heading(goal, pose)
    if heading is None:
        return []
    return [moved(planner._base("line_sink"), goal.x_m, goal.y_m, angle_rad=heading + math.pi / 2,
                  name=f"line@{goal.index}")]


def _template_rotation(planner: MultiTask, goal: PartGoal, pose: np.ndarray) -> list[PlateMotion]:
    """The rotation about the part, both ways (the design and its mirror image): which way a rigid
    part turns under a rotation field designed for point parts depends on the part, so the model's
    prediction chooses."""
    if goal.theta_rad is None:
        return []
    return both_ways(planner._base("rotation"), pose[:2], "turn", str(goal.index))


def both_ways(base: PlateMotion, centre, kind: str, tag: str) -> list[PlateMotion]:
    """``base`` (designed about the centre) moved to ``centre`` as it is and mirrored, named
    ``kind+@tag`` / ``kind-@tag``: the design and the other way round (``moved``)."""
    return [moved(base, float(centre[0]), float(centre[1]), mirror=reverse,
                  name=f"{kind}{'-' if reverse else '+'}@{tag}") for reverse in (False, True)]


def spin_motion(settings: MpcSettings) -> PlateMotion:
    """The spin about the plate centre: alpha_z with a vertical acceleration in phase (harmonic 1 at
    the planner's frequency), before fitting into the envelope. Moved to a rigid part, it turns the
    part in place, whatever its orientation; its mirror image turns it the other way."""
    X = np.zeros((1, 6), complex)
    X[0, 2] = settings.spin_vertical_mps2
    X[0, 5] = settings.spin_angular_radps2
    return PlateMotion.from_phasors(settings.frequency_hz, [1], X, name="spin")


def _template_spin(planner: MultiTask, goal: PartGoal, pose: np.ndarray) -> list[PlateMotion]:
    """A rigid part turned in place, both ways: the spin (fitted at the centre) moved to the part."""
    if goal.theta_rad is None or not isinstance(planner.parts[goal.index], RigidPart):
        return []
    return both_ways(planner._spin(), pose[:2], "spin", str(goal.index))


def fixed_point(p, q, angle_rad: float) -> np.ndarray | None:
    """The fixed point (x, y) of the rotation by ``angle_rad`` that takes the point ``p`` to ``q``
    (the centre on the chord's perpendicular bisector; its midpoint for half a turn). None for no turn."""
    if abs(angle_rad) < 1e-9:
        return None
    p, q = np.asarray(p[:2], float), np.asarray(q[:2], float)
    e = q - p
    n = np.array([-e[1], e[0]])        # the chord turned +90 deg (length d): the centre lies on its side
    return 0.5 * (p + q) + n * (0.5 / math.tan(0.5 * angle_rad))


def pivot_point(pose: np.ndarray, goal: PartGoal, angle_rad: float) -> np.ndarray | None:
    """The fixed point (x, y) of the rigid motion that turns ``pose`` by ``angle_rad`` (the goal angle's
    error, the way to turn) and takes its position to the goal's: turned about it by that angle, the
    part arrives at its goal pose. None for no turn."""
    return fixed_point(pose, (goal.x_m, goal.y_m), angle_rad)


def pair_rotation(pa, pb, ga, gb) -> tuple[np.ndarray | None, float]:
    """Two parts at ``pa``, ``pb`` (x, y) with goals ``ga``, ``gb``: the angle (rad, signed) their
    segment has to turn to lie as the goals' does, and the fixed point of the rotation by it that
    takes the segment's midpoint to the goals' (None for no turn). Turned about it, both parts move
    towards their goals together; for a swap (half a turn) it is about the midpoint between them."""
    pa, pb, ga, gb = (np.asarray(v[:2], float) for v in (pa, pb, ga, gb))
    u, w = pb - pa, gb - ga
    angle = math.atan2(u[0] * w[1] - u[1] * w[0], float(u @ w))
    return fixed_point(0.5 * (pa + pb), 0.5 * (ga + gb), angle), angle


def _template_pivot(planner: MultiTask, goal: PartGoal, pose: np.ndarray) -> list[PlateMotion]:
    """A rigid part turned about its pivot (MpcSettings.pivot_from_rad), both ways: the spin moved to
    the pivot, where the part turns as in place and is carried along the circle about it."""
    c = planner._pivot(goal, pose)
    return [] if c is None else both_ways(planner._spin(), c, "pivot", str(goal.index))


def _template_orient(planner: MultiTask, goal: PartGoal, pose: np.ndarray) -> list[PlateMotion]:
    if goal.theta_rad is None:
        return []
    from ppod_ros.planning.design import ORIENT_FREQUENCY_HZ

    X = orient_phasors(goal.x_m, goal.y_m, goal.theta_rad)
    return [PlateMotion.from_phasors(ORIENT_FREQUENCY_HZ, [1], X[None], name=f"orient@{goal.index}")]


# The templates that carry a part fast (15-20 mm/s) and everything near it: not tried for a part
# already close to its goal (MultiTask._close).
STRONG_TEMPLATES = frozenset({"transport"})

TEMPLATES: dict[str, Callable] = {"sink": _template_sink, "transport": _template_transport,
                                  "line": _template_line, "rotation": _template_rotation,
                                  "orient": _template_orient, "spin": _template_spin,
                                  "pivot": _template_pivot}


# The centre design each template kind is moved from (None: built directly).
TEMPLATE_BASES: dict[str, str | None] = {"sink": "sink", "transport": "transport", "line": "line_sink",
                                         "rotation": "rotation", "orient": None, "spin": None,
                                         "pivot": None}


def base_kinds(settings: MpcSettings | None = None) -> list[str]:
    """The centre designs ``settings`` (its templates, pair lines and pair rotations) uses: what a node designs when
    it configures, so the first replanning step does not pay them."""
    s = settings or MpcSettings()
    kinds = ({TEMPLATE_BASES[k] for k in s.templates} | ({"line_sink"} if s.pair_lines else set())
             | ({"rotation"} if s.swap_from_rad > 0 else set()))
    return [k for k in BASE_KINDS if k in kinds]


def line_through(planner: MultiTask, a: PartGoal, b: PartGoal) -> PlateMotion:
    """The line sink along the line through two goals: parts at them stay, others are gathered on it."""
    angle = math.atan2(b.y_m - a.y_m, b.x_m - a.x_m)
    return moved(planner._base("line_sink"), a.x_m, a.y_m, angle_rad=angle, name=f"line@{a.index},{b.index}")


def template_motion(kind: str, planner: MultiTask, goal: PartGoal, pose: np.ndarray) -> list[PlateMotion]:
    """The template motions of ``kind`` for ``goal`` from ``pose`` (none where the kind does not
    apply); ConfigError for an unknown kind."""
    try:
        build = TEMPLATES[kind]
    except KeyError:
        raise ConfigError(f"kind: unknown template field {kind!r}; expected one of {', '.join(TEMPLATES)}") from None
    return build(planner, goal, pose)


# ---------------------------------------------------------------------------------- the planner
@dataclass
class _Tracked:
    holding: bool = False
    in_tol_since: float | None = None
    time_to_goal_s: float | None = None
    scale: float = 1.0
    estimated: bool = False      # the scale has been estimated from a motion at least once
    turn: float = 1.0            # the turn's velocity scale over every motion (MpcSettings.turn_scale)
    turn_now: tuple[bytes, float] | None = None  # ... and under one motion (its key): the one playing
    turn_by_name: dict = field(default_factory=dict)  # ... and per motion name (turn_scale_by_name)
    weak_turns: dict = field(default_factory=dict)  # motion name: [sum of predicted x turned, of predicted^2]
                                                    # over weak segments not yet taught (weak_turn_pool_gain)
    scale_by_name: dict = field(default_factory=dict)  # the translation's per motion name (scale_by_name)
    last_seen: float | None = None
    aim: tuple[float, float] = (0.0, 0.0)  # integral action: the aim's offset from the goal (m)
    near_since: float | None = None       # ... when the part first came within integral_within_m
    aim_t: float | None = None            # ... the frame it was last updated at


@dataclass
class _Segment:
    t_s: float
    poses: np.ndarray            # (N, 3) at the start of the segment
    velocity: np.ndarray         # (G, 3) model velocity (unscaled) per goal at the start
    previous: np.ndarray         # (G, 3) the same under the motion before the switch
    motion_key: bytes = b""
    unseen: frozenset = frozenset()  # rows planned at their last seen pose
    middle: np.ndarray | None = None  # (G, 3) the same half-way through the ramp (None: not solved)


def _dim(part: PointPart | RigidPart) -> int:
    return 3 if isinstance(part, RigidPart) else 2


def _with_friction(part: PointPart | RigidPart, factor: float) -> PointPart | RigidPart:
    """The part model with its friction (kinetic and static) times ``factor``."""
    ms = None if part.mu_static is None else np.asarray(part.mu_static) * factor
    if isinstance(part, RigidPart):
        return dataclasses.replace(part, mu=np.asarray(part.mu) * factor, mu_static=ms)
    return dataclasses.replace(part, mu=float(part.mu) * factor, mu_static=None if ms is None else float(ms))


def ramp_weights(t_s: float, ramp_s: float, midpoint: bool = False) -> tuple[float, float, float]:
    """Weights (old, middle, new) of the velocities before, half-way through and after the generator's
    ramp of ``ramp_s`` in the displacement over ``t_s`` after a switch: the velocity interpolated
    quadratically through the three (``midpoint``; over the whole ramp Simpson's rule, r/6, 2r/3,
    r/6), or linearly from the old to the new (middle weight 0). With the middle velocity the mean
    of the other two, both give the same displacement."""
    if ramp_s <= 0:
        return 0.0, 0.0, t_s
    if not midpoint:
        u = min(t_s, ramp_s)
        w_old = u - u * u / (2.0 * ramp_s)
        return w_old, 0.0, t_s - w_old
    u = min(t_s, ramp_s) / ramp_s
    w_old = ramp_s * 2.0 * (u ** 3 / 3.0 - 0.75 * u * u + 0.5 * u)
    w_mid = ramp_s * -4.0 * (u ** 3 / 3.0 - 0.5 * u * u)
    return w_old, w_mid, t_s - w_old - w_mid


@lru_cache(maxsize=16)
def _frame_weights(horizon_s: float, step_s: float, ramp_s: float, midpoint: bool) -> tuple[np.ndarray, np.ndarray]:
    """Per frame ``step_s, 2 step_s, ...`` up to ``horizon_s`` after a switch: the :func:`ramp_weights`
    (T, 3, 1, 1, 1) and the ramp's progress (T, 1, 1, 1), shaped to broadcast over (motions, goals,
    axes); read-only."""
    taus = step_s * np.arange(1, int(round(horizon_s / step_s)) + 1)
    w = np.array([ramp_weights(float(t), ramp_s, midpoint) for t in taus]).reshape(-1, 3, 1, 1, 1)
    a = (np.minimum(1.0, taus / ramp_s) if ramp_s > 0 else np.ones_like(taus)).reshape(-1, 1, 1, 1)
    w.flags.writeable = a.flags.writeable = False
    return w, a


def ramped_displacement(v_old: np.ndarray, v_new: np.ndarray, t_s: float, ramp_s: float,
                        v_mid: np.ndarray | None = None) -> np.ndarray:
    """Displacement over ``t_s`` after a switch from v_old to v_new over the generator's ramp of
    ``ramp_s``: the velocity crossfaded linearly, or with ``v_mid`` (the velocity under the motion
    played half-way) interpolated quadratically through the three (:func:`ramp_weights`)."""
    w_old, w_mid, w_new = ramp_weights(t_s, ramp_s, v_mid is not None)
    out = v_old * w_old + v_new * w_new
    return out if v_mid is None else out + v_mid * w_mid


class MultiTask:
    """Move ``parts[g.index]`` to each goal g at once (see the module docstring).

    ``parts`` are the planner's models of every tracked part (rows of the poses); ``goals`` the
    commanded ones. ``keep_clear``: the uncommanded parts enter the collision penalty too.
    ``names``: what the progress and result texts call each row (default ``#row``; the node: the
    tracker's ids, which its user knows the parts by).
    """

    def __init__(self, parts: Sequence[PointPart | RigidPart], goals: Sequence[PartGoal], *, device=None,
                 settings: MpcSettings | None = None, timeout_s: float = 60.0, keep_clear: bool = False,
                 names: Sequence[str] | None = None):
        from ppod_ros.device import default_device_config

        self.parts = list(parts)
        if not self.parts:
            raise ConfigError("parts: expected at least one part")
        self.names = [f"#{i}" for i in range(len(self.parts))] if names is None else [str(n) for n in names]
        if len(self.names) != len(self.parts):
            raise ConfigError(f"names: expected one per part ({len(self.parts)}), got {len(self.names)}")
        self.settings = settings or MpcSettings()
        if not isinstance(self.settings, MpcSettings):
            raise ConfigError(f"settings: expected MpcSettings, got {type(self.settings).__name__}")
        self.goals = list(goals)
        check_goals(self.parts, self.goals, clearance_m=self.settings.clearance_m)
        if not (math.isfinite(timeout_s) and timeout_s > 0):
            raise ConfigError(f"timeout_s: must be > 0, got {timeout_s!r}")
        self.device = device or default_device_config()
        self.timeout = float(timeout_s)
        self.keep_clear = bool(keep_clear)
        self.symmetry = {g.index: _symmetry(self.parts[g.index]) for g in self.goals}
        # The goals as arrays (stop_on_way's landing check): poses (G, 3) (angle 0 where none), oriented
        # (G,), position and angle tolerances (G,), the parts' symmetry periods (G,).
        self._goal_arrays = (
            np.array([[g.x_m, g.y_m, 0.0 if g.theta_rad is None else g.theta_rad] for g in self.goals]),
            np.array([g.theta_rad is not None for g in self.goals]),
            np.array([g.position_tol_m for g in self.goals]), np.array([g.angle_tol_rad for g in self.goals]),
            np.array([self.symmetry[g.index] for g in self.goals]))
        n2 = self.settings.two_harmonics_from_parts
        self.harmonics = 2 if n2 and len(self.goals) >= n2 else self.settings.harmonics  # of the search
        self.radius = np.array([part_radius_m(p) for p in self.parts])
        self.state = {g.index: _Tracked() for g in self.goals}
        self.t0: float | None = None
        self.t_plan = -math.inf
        self.t_switch = -math.inf
        self.current = PlateMotion.zero(self.settings.frequency_hz)
        self.segment: _Segment | None = None
        self.finished: MultiStep | None = None
        self.phase = "planning"
        self.plan_times_ms: list[float] = []
        self.plan_searched: list[bool] = []   # per replanning step (as plan_times_ms): the candidates were
                                              # searched (not a step within the dwell that kept the motion)
        self._searched = False
        self.latency_s = 0.0   # running mean of the reported command latencies (command_latency)
        self.last_pose: dict[int, np.ndarray] = {}
        self.progress: list[tuple[float, float]] = []
        self.focus: int | None = None
        self.focus_since = -math.inf
        self.unseen: set[int] = set()
        self.switches = 0
        self.last_prediction: dict | None = None   # {"t_s", "motion", "poses", "velocity" (G, 3) scaled}
        self._bases: dict[str, PlateMotion] = {}
        # Goals grouped by part model (equal models, e.g. two washers, share one solver call), and
        # the model velocities of this replanning step's motions (the poses are fixed within a step).
        # With keep_clear the uncommanded parts are predicted too (rows after the goals'), so that a
        # candidate that pushes them into a commanded part's path costs what the collision costs.
        commanded = [g.index for g in self.goals]
        self._others = [i for i in range(len(self.parts)) if i not in commanded] if self.keep_clear else []
        self._rows = commanded + self._others
        groups: dict[tuple, list[int]] = {}
        for j, row in enumerate(self._rows):
            groups.setdefault(tuple(self.parts[row].key), []).append(j)
        self._groups = [(self.parts[self._rows[js[0]]], js) for js in groups.values()]
        self._point_groups = any(isinstance(part, PointPart) for part, _ in self._groups)
        self._memo: dict[bytes, tuple[np.ndarray, bool, bool, bool]] = {}  # key: (velocities, valid, budgeted,
                                                                           # invalid only as the solver gave up)
        self._held: tuple[bytes, np.ndarray, np.ndarray] | None = None  # the motion playing: (key, poses of
                                                                          # the commanded parts, velocities) where
                                                                          # it last converged
        self._held_at: bytes | None = None  # the poses (memo key) where the last prediction was held
        self.held_predictions = 0          # replanning steps that held the motion playing's last prediction
        self._fits: dict[bytes, PlateMotion] = {}
        self._memo_poses: bytes | None = None
        self._gave_up_at: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # fitted candidate's name: (the commanded
                                          # rows it gave up at, their poses) where the solver last gave up on it
                                          # at full caps
        self._rows_gave_up: dict[bytes, np.ndarray] = {}  # this step's motions: the commanded rows given up on
        # Per unlearned motion (see MpcSettings.unlearned_motions): the fraction (G, 3) of the model
        # velocity the uncorrected plants play on average, and the time of its switch.
        self._first_error: dict[bytes, tuple[np.ndarray, float]] = {}
        self._rest_frames: list[np.ndarray] = []   # the poses seen since the plate came to rest (_at_rest)
        self._gentle_full: tuple[bytes, PlateMotion] | None = None  # (gentle motion's key, the motion at full
                                                                     # amplitude it was scaled down from)
        self._teach: tuple[bytes, PlateMotion, float] | None = None  # the first motion's quiet copy playing:
                                                                      # (its key, the full motion, when it ends)

    # ------------------------------------------------------------------ templates
    def _base(self, kind: str) -> PlateMotion:
        if kind not in self._bases:
            self._bases[kind] = base_design(kind, self.device, self.settings)
        return self._bases[kind]

    # ------------------------------------------------------------------ stepping
    def step(self, t_s: float, poses) -> MultiStep:
        """One camera frame: ``poses`` (N, 3) [x, y, theta] in the plate frame, NaN rows unseen."""
        if self.finished is not None:
            return self.finished
        poses = np.asarray(poses, dtype=float).reshape(-1, 3)
        if poses.shape[0] != len(self.parts):
            raise ConfigError(f"poses: expected {len(self.parts)} rows, got {poses.shape[0]}")
        if self.t0 is None:
            self.t0 = t_s
        elapsed = t_s - self.t0
        poses = self._at_rest(t_s, poses)
        statuses = self._statuses(t_s, poses)
        self._integrate_aims(t_s, poses)
        lost = self.settings.lost_after_s
        missing = [g.index for g in self.goals
                   if self.state[g.index].last_seen is None or t_s - self.state[g.index].last_seen > lost]
        if missing and elapsed > self.settings.lost_after_s:
            return self._end(statuses, f"part {missing[0]} not seen for over {self.settings.lost_after_s:g} s")
        if all(s.reached for s in statuses):
            # Done only with the plate at rest (its ramp down moves the parts too): stop it first,
            # and end when the parts are still within tolerance after the ramp. A part within
            # tolerance but not within done_within of it is planned on below, moving or at rest.
            edge = not self._all_within(statuses, self.settings.done_within)
            if not self.current.is_zero():
                if not edge:
                    motion = self._stop(t_s, poses, statuses)
                    return MultiStep(motion, self.phase, False, None, *self._worst(statuses),
                                     self._text(statuses), tuple(statuses))
            elif t_s - self.t_switch < self.settings.ramp_s + self.settings.settle_s - 1e-9:
                return MultiStep(None, self.phase, False, None, *self._worst(statuses), self._text(statuses),
                                 tuple(statuses))
            elif not edge:
                return self._end(statuses, None, elapsed)
        if elapsed > self.timeout:
            n_ok = sum(s.reached for s in statuses)
            return self._end(statuses, f"timeout after {elapsed:.1f} s: {n_ok} of {len(statuses)} parts reached")
        motion, plan_ms = None, 0.0
        if not self.current.is_zero() and self._all_well_within(statuses, poses, t_s):
            # Checked at every camera frame, not only when replanning: a part crossing its
            # tolerance between two replanning steps would be carried through it.
            motion = self._stop(t_s, poses, statuses)
            return MultiStep(motion, self.phase, False, None, *self._worst(statuses), self._text(statuses),
                             tuple(statuses))
        if t_s - self.t_plan >= self.settings.replan_period_s - 1e-9:
            rows = [g.index for g in self.goals]
            seen = np.all(np.isfinite(poses[rows, :2]), axis=1)
            for row, ok in zip(rows, seen):
                if ok:
                    self.last_pose[row] = poses[row]
            if seen.any() and all(row in self.last_pose for row in rows):
                # An unseen commanded part is planned at its last pose with no weight (not steered).
                self.unseen = {row for row, ok in zip(rows, seen) if not ok}
                poses = poses.copy()
                for row in self.unseen:
                    poses[row] = self.last_pose[row]
                w0 = time.perf_counter()
                self._estimate(t_s, poses)
                self._searched = False
                motion = self._plan(t_s, poses, statuses)
                plan_ms = 1e3 * (time.perf_counter() - w0)
                self.plan_times_ms.append(plan_ms)
                self.plan_searched.append(self._searched)
                self.t_plan = t_s
        return MultiStep(motion, self.phase, False, None, *self._worst(statuses), self._text(statuses),
                         tuple(statuses), plan_ms)

    def _at_rest(self, t_s: float, poses: np.ndarray) -> np.ndarray:
        """``poses`` with each commanded part seen now at the mean of its poses seen since the plate came
        to rest (``MpcSettings.rest_average_after_s`` after the ramp down; angles averaged on the circle
        of the part's symmetry, on the branch of the latest); as they are while a motion plays."""
        s = self.settings
        if (s.rest_average_after_s is None or not self.current.is_zero()
                or t_s - self.t_switch < s.ramp_s + s.rest_average_after_s - 1e-9):
            self._rest_frames = []
            return poses
        self._rest_frames.append(poses)
        frames = np.array(self._rest_frames)
        out = poses.copy()
        for g in self.goals:
            row = g.index
            seen = np.all(np.isfinite(frames[:, row, :2]), axis=1)
            if not seen[-1]:
                continue
            out[row, :2] = frames[seen, row, :2].mean(axis=0)
            th = frames[seen, row, 2]
            if np.isfinite(poses[row, 2]) and np.all(np.isfinite(th)):
                period = self.symmetry[row]
                z = np.exp(1j * 2 * np.pi * th / period).mean()
                mean = float(np.angle(z)) * period / (2 * np.pi)
                out[row, 2] = poses[row, 2] + float(_wrap(mean - poses[row, 2], period))
        return out

    def _statuses(self, t_s: float, poses: np.ndarray) -> list[PartStatus]:
        out = []
        for g in self.goals:
            st, p = self.state[g.index], poses[g.index]
            if not np.all(np.isfinite(p[:2])):
                out.append(PartStatus(g.index, math.nan, None, False, False, st.time_to_goal_s, st.scale))
                continue
            st.last_seen = t_s
            dist = math.hypot(p[0] - g.x_m, p[1] - g.y_m)
            ang = None if g.theta_rad is None else float(_wrap(p[2] - g.theta_rad, self.symmetry[g.index]))
            within = g.within(dist, ang, self.settings.within_fraction)
            if within:
                if st.in_tol_since is None:
                    st.in_tol_since = t_s
                    st.time_to_goal_s = t_s - self.t0
            else:
                st.in_tol_since, st.time_to_goal_s = None, None
            reached = within and t_s - st.in_tol_since >= self.settings.settle_s
            out.append(PartStatus(g.index, dist, ang, within, reached, st.time_to_goal_s, st.scale))
        return out

    # ------------------------------------------------------------------ estimation
    def _estimate(self, t_s: float, poses: np.ndarray) -> None:
        """Velocity scale per commanded part from the last segment's displacement vs the prediction."""
        seg, s = self.segment, self.settings
        if seg is None or seg.motion_key != self.current.key:
            return
        if self._teach is not None and seg.motion_key == self._teach[0]:
            # The quiet copy plays on the plant the feedback has not learned yet: it teaches no scale
            # (fitting the friction to it, as after a gentle start, measured worse: docs/planner.md).
            return
        dt = t_s - seg.t_s
        disp = ramped_displacement(seg.previous, seg.velocity, dt, self.settings.ramp_s, seg.middle)
        gentle = self._gentle_full if self._gentle_full is not None and self._gentle_full[0] == seg.motion_key else None
        for k, g in enumerate(self.goals):
            if g.index in self.unseen or g.index in seg.unseen:
                continue
            if gentle is not None and not self.state[g.index].estimated:
                self._fit_friction(k, g, seg, dt, poses, gentle[1])
                continue
            pred = disp[k, :2]
            d = poses[g.index, :2] - seg.poses[g.index, :2]
            st = self.state[g.index]
            if s.turn_scale and g.theta_rad is not None:
                self._estimate_turn(st, seg.motion_key, self.current.name, float(disp[k, 2]),
                                    float(_wrap(poses[g.index, 2] - seg.poses[g.index, 2], self.symmetry[g.index])))
            elif s.scale_from_turn and g.theta_rad is not None:
                # The turn too, at the part's radius: learned from the translation alone, a bracket
                # 8 deg off its goal angle kept the scale 1.82 of a fast turn and, under motions the
                # model said turn it at 0.2 rad/s, did not turn for 40 s (benchmark scene 15).
                r = part_radius_m(self.parts[g.index])
                turn = float(_wrap(poses[g.index, 2] - seg.poses[g.index, 2], self.symmetry[g.index]))
                pred, d = np.append(pred, r * disp[k, 2]), np.append(d, r * turn)
            n2 = float(pred @ pred)
            if not np.all(np.isfinite(d)) or n2 < s.min_predicted_m ** 2:
                continue
            ratio = float(np.clip((d @ pred) / n2, *s.scale_range))
            if self._by_name(g) and self.current.name:
                was = st.scale_by_name.get(self.current.name, st.scale)
                st.scale_by_name[self.current.name] = self._smoothed(was, ratio, s.scale_range)
            st.scale = self._smoothed(st.scale, ratio, s.scale_range)
            st.estimated = True

    def _estimate_turn(self, st: _Tracked, key: bytes, name: str, predicted_rad: float, turned_rad: float) -> None:
        """The turn's velocity scales from one segment of the motion ``key``: the part's turn against
        the predicted one (``predicted_rad``, ramp included, unscaled), when that is at least
        ``min_predicted_turn_rad`` (a weak predicted turn says nothing against the tracker's noise);
        smoothed as the scale. The motion's own scale starts from the part's.
        Weaker segments of one motion name are pooled (``weak_turn_pool_gain``) until their predicted
        turns reach it together, and teach their least-squares ratio at that fraction of the gain."""
        s = self.settings
        if not (math.isfinite(turned_rad) and math.isfinite(predicted_rad)):
            return
        gain = 1.0
        if abs(predicted_rad) < s.min_predicted_turn_rad:
            if not (s.weak_turn_pool_gain > 0 and name):
                return
            pool = st.weak_turns.setdefault(name, [0.0, 0.0])
            pool[0] += predicted_rad * turned_rad
            pool[1] += predicted_rad * predicted_rad
            if pool[1] < s.min_predicted_turn_rad ** 2:
                return
            ratio, gain = pool[0] / pool[1], s.weak_turn_pool_gain
            del st.weak_turns[name]
        else:
            ratio = turned_rad / predicted_rad
        st.turn = self._smoothed(st.turn, ratio, s.scale_range, gain)
        now = st.turn_now[1] if st.turn_now is not None and st.turn_now[0] == key else st.turn
        st.turn_now = (key, self._smoothed(now, ratio, s.turn_scale_range, gain))
        if s.turn_scale_by_name and name:
            st.turn_by_name[name] = self._smoothed(st.turn_by_name.get(name, now), ratio, s.turn_scale_range, gain)

    def _smoothed(self, was: float, ratio: float, bounds: tuple[float, float], gain: float = 1.0) -> float:
        """A velocity scale ``was`` moved towards a measured ``ratio`` by ``scale_gain`` (times ``gain``),
        within ``bounds``."""
        return float(np.clip(was + gain * self.settings.scale_gain * (ratio - was), *bounds))

    def _by_name(self, g: PartGoal) -> bool:
        """Whether the part of ``g`` keeps its translation scale per motion name (``scale_by_name``)."""
        by = self.settings.scale_by_name
        return by == "all" or (by == "rigid" and isinstance(self.parts[g.index], RigidPart))

    def _axis_scales(self, motions: Sequence[PlateMotion] | None = None) -> np.ndarray:
        """The velocity scales of x, y and theta per goal (G, 3), or per motion and goal (M, G, 3):
        the translation's scale; for a part with a goal angle (``turn_scale``), its turn's over every
        motion, or under the motion itself when it is the one the scale was learned from."""
        one = motions is None
        motions = [self.current] if one else motions
        out = np.array([[self.state[g.index].scale] * 3 for g in self.goals]).reshape(1, len(self.goals), 3)
        out = np.repeat(out, len(motions), axis=0)
        if self.settings.scale_by_name != "off":
            for k, g in enumerate(self.goals):
                named = self.state[g.index].scale_by_name
                if named and self._by_name(g):
                    out[:, k, :2] = np.array([named.get(m.name, out[0, k, 0]) for m in motions])[:, None]
                    if g.theta_rad is None or not self.settings.turn_scale:
                        out[:, k, 2] = out[:, k, 0]
        if self.settings.turn_scale:
            for k, g in enumerate(self.goals):
                st = self.state[g.index]
                if g.theta_rad is None:
                    continue
                out[:, k, 2] = [st.turn_by_name.get(m.name, st.turn) for m in motions]  # by name where learned
                if st.turn_now is not None:
                    out[[m.key == st.turn_now[0] for m in motions], k, 2] = st.turn_now[1]
        return out[0] if one else out

    def _fit_friction(self, k: int, g: PartGoal, seg: _Segment, dt: float, poses: np.ndarray,
                      full: PlateMotion) -> None:
        """After a gentle start: the friction (``friction_grid`` times the model's) whose prediction of
        the gentle motion is nearest the part's displacement, and from it the velocity scale of the
        motion at full amplitude (the next motions are strong)."""
        s, part = self.settings, self.parts[g.index]
        d = poses[g.index, :2] - seg.poses[g.index, :2]
        if not np.all(np.isfinite(d)):
            return
        cfg = seg.poses[[g.index], :_dim(part)]
        factor = self._plant_factor(self.current, seg.t_s)[k, :2]   # the unlearned plant's mean
        models = [_with_friction(part, f) for f in s.friction_grid]
        gentle = self.current
        errs = []
        for m in models:
            v = np.nan_to_num(predict_velocities([gentle], m, cfg)[0][0, 0, :2]) * factor
            errs.append(float(np.hypot(*(d - ramped_displacement(seg.previous[k, :2], v, dt, s.ramp_s)))))
        best = models[int(np.argmin(errs))]
        v, ok = predict_velocities([full], part, cfg)
        vf, okf = predict_velocities([full], best, cfg)
        v1, v2 = np.nan_to_num(v[0, 0, :2]), np.nan_to_num(vf[0, 0, :2])
        n2 = float(v1 @ v1)
        st = self.state[g.index]
        if ok.all() and okf.all() and n2 > 1e-12:
            st.scale = float(np.clip((v2 @ v1) / n2, *s.scale_range))
        st.estimated = True

    # ------------------------------------------------------------------ planning
    def _all_within(self, statuses: list[PartStatus], fraction: float) -> bool:
        """Every commanded part within ``fraction`` of its tolerances, where it is now."""
        return all(g.within(st.position_error_m, st.angle_error_rad, fraction)
                   for g, st in zip(self.goals, statuses))

    def _all_well_within(self, statuses: list[PartStatus], poses: np.ndarray | None = None,
                         t_s: float | None = None) -> bool:
        """Every commanded part within ``stop_within`` of its tolerances; with ``stop_ahead`` and a
        motion playing, judged where the ramp down would leave it: the pose plus the predicted velocity
        now (the segment's, ramp included, times the part's scale) over half the ramp."""
        s = self.settings
        seg = self.segment
        if not (s.stop_ahead and poses is not None and seg is not None and seg.motion_key == self.current.key
                and not self.current.is_zero()):
            return self._all_within(statuses, s.stop_within)
        a = min(1.0, max(0.0, (t_s - seg.t_s) / s.ramp_s)) if s.ramp_s > 0 else 1.0
        v_now = seg.previous + a * (seg.velocity - seg.previous)
        scales = self._axis_scales()
        for k, g in enumerate(self.goals):
            p = poses[g.index]
            if not np.all(np.isfinite(p[:2])):
                return False
            stop = p + scales[k] * v_now[k] * (0.5 * s.ramp_s)
            angle = None if g.theta_rad is None else float(_wrap(stop[2] - g.theta_rad, self.symmetry[g.index]))
            if angle is not None and not math.isfinite(angle):
                angle = None   # an unseen angle: judged by its position
            if not g.within(math.hypot(stop[0] - g.x_m, stop[1] - g.y_m), angle, s.stop_within):
                return False
        return True

    def command_latency(self, latency_s: float) -> None:
        """The motion the last step returned started playing ``latency_s`` (device time) after that
        step was called: the planning time and the transport (the field planner node reports it when
        it publishes a motion; the ROS-free loop under ``command_latency_s``). Only a step that
        searched counts (a stop or a kept motion takes a few ms); the running mean lowers the approach
        gain (:meth:`approach_per_s`). A latency that is not finite or negative is ignored."""
        if not (self._searched and math.isfinite(latency_s) and latency_s >= 0.0):
            return
        w = self.settings.latency_smoothing
        self.latency_s += w * (float(latency_s) - self.latency_s)

    def approach_per_s(self) -> float:
        """The waypoints' approach gain (1/s): ``approach_per_s`` over ``1 + L / latency_ref_s`` for the
        running mean L of the command latency, with at least ``latency_from_parts`` parts commanded (a
        discrete loop with a delay: the gain that settles parts with no delay makes them overshoot
        and oscillate with one)."""
        s = self.settings
        if s.latency_ref_s is None or len(self.goals) < s.latency_from_parts:
            return s.approach_per_s
        return s.approach_per_s / (1.0 + self.latency_s / s.latency_ref_s)

    def plate_stopped(self, t_s: float, poses) -> None:
        """The plate was stopped from outside at ``t_s`` (the field planner node does so when a plan
        comes later than its lease: the motion playing was planned on poses too old to trust):
        continue from rest, predicting the ramp down from the last plan's velocities, and replan at
        the next frame. ``poses`` (N, 3) as in :meth:`step`, at ``t_s``."""
        if self.finished is not None or self.current.is_zero():
            return
        poses = np.asarray(poses, dtype=float).reshape(-1, 3)
        if poses.shape[0] != len(self.parts):
            raise ConfigError(f"poses: expected {len(self.parts)} rows, got {poses.shape[0]}")
        self._v_current = (self.segment.velocity if self.segment is not None
                           else np.zeros((len(self.goals), 3)))
        self._switch(t_s, poses, PlateMotion.zero(self.current.frequency_hz, name="rest"),
                     np.zeros((len(self.goals), 3)), middle=False)
        self.t_plan = -math.inf

    def _stop(self, t_s: float, poses: np.ndarray, statuses: list[PartStatus]) -> PlateMotion | None:
        """Every commanded part is well there: stop the plate (at rest, it holds every part). The
        prediction ramps down from the current motion's velocities."""
        self.phase = "holding"
        rest = PlateMotion.zero(self.current.frequency_hz, name="rest")
        self._v_current = self._current_velocity(poses)
        return self._switch(t_s, poses, rest, np.zeros((len(self.goals), 3)))

    def _current_velocity(self, poses: np.ndarray) -> np.ndarray:
        """The model velocities (G, 3) of the commanded parts under the motion now playing (the
        prediction's ramp starts from them; zero for the plate at rest)."""
        return self._velocities([self.current], poses)[0][0, :len(self.goals)]

    def _plan(self, t_s: float, poses: np.ndarray, statuses: list[PartStatus]) -> PlateMotion | None:
        s = self.settings
        if self._all_well_within(statuses, poses, t_s):
            return self._stop(t_s, poses, statuses)
        self.phase = "moving"
        if s.hold_at_rest and self.current.is_zero() and self._all_within(statuses, s.rest_hold_within):
            # Every part within rest_hold_within of its tolerances with the plate at rest, which holds
            # them: wait out settle_s instead of restarting the plate (on benchmark seed 1 scene 8 a
            # weak motion restarted it 0.1 s short of that, and the next stop's ramp down carried the
            # bracket out again).
            self._v_current = np.zeros((len(self.goals), 3))
            return self._switch(t_s, poses, self.current, self._v_current, keep=True)
        self._update_focus(t_s, statuses)
        self._v_current = self._current_velocity(poses)
        self._hold_playing(poses)
        current_cost, current_vel = self._costs([self.current], poses, statuses)
        if self._teach is not None and self._teach[0] == self.current.key:
            taught = self._taught(t_s, poses, statuses, current_cost, current_vel)
            if taught is not False:
                return taught
        near = all(st.position_error_m <= s.near_m for st in statuses)
        dwell = s.near_dwell_s if near else s.min_dwell_s
        if self.current.is_zero() and s.rest_dwell_s is not None:
            dwell = s.rest_dwell_s   # the plate at rest: no first error of a motion playing to wait out
        dwelt = t_s - self.t_switch >= dwell - 1e-9
        if not dwelt and math.isfinite(float(current_cost[0])):
            # No switch before the dwell is over, and the motion playing is still safe: the search
            # below could only keep it (it searches only to stop the plate when nothing is).
            return self._switch(t_s, poses, self.current, current_vel[0], keep=True)
        self._searched = True
        candidates = [PlateMotion.zero(s.frequency_hz, name="rest")]
        for g, st in zip(self.goals, statuses):
            for kind in s.templates:
                if kind in STRONG_TEMPLATES and self._close(st):
                    continue
                candidates += template_motion(kind, self, g, poses[g.index])
        near = [g for g, st in zip(self.goals, statuses) if s.pair_lines and st.position_error_m <= s.near_m]
        for a in range(len(near)):   # two parts there: a field that vanishes on the line through them
            for b in range(a + 1, len(near)):
                candidates.append(line_through(self, near[a], near[b]))
        candidates += self._pair_rotations(poses, statuses)
        costs, vels = self._costs(candidates, poses, statuses)
        costs = np.concatenate([current_cost, costs])
        pool = [self.current] + candidates
        if any(not st.within for g, st in zip(self.goals, statuses) if g.index not in self.unseen):
            # The plate at rest holds every part but brings none closer: while a part is out of
            # tolerance it is no option, or a horizon on which every motion moves some part away
            # keeps the plate at rest for good (measured: 54 s of a 60 s benchmark scene).
            costs = np.where([m.is_zero() for m in pool], np.inf, costs)
            if self.current.is_zero():
                current_cost = np.full_like(current_cost, np.inf)
        # The best few ranked as the generator will play them, fitted into the envelope: a design
        # moved off the centre or mirrored can need less amplitude, and a field is far from linear
        # in it (a rotation that ranked 34 % better than the current motion was 9 % better fitted).
        order = [int(i) for i in np.argsort(costs) if i > 0 and math.isfinite(float(costs[i]))][:s.fitted_candidates]
        # The next switch plays a motion the feedback has not learned the plant for: the ranked
        # candidates (and the refined one) also cost the spread of their predicted paths over the
        # plants within the tolerance, and the others are out (they carry no such cost).
        unlearned = s.first_error_weight > 0 and (
            (s.plant_tolerance is not None and self.switches < s.unlearned_motions)
            or any(not self.state[g.index].estimated for g in self.goals))
        if order:
            fitted = self._fitted_many([pool[i] for i in order])
            fitted_costs, _ = self._costs(fitted, poses, statuses,
                                          budget=s.budget_fitted or self._suspects(fitted, poses) or False,
                                          ramped=True)
            self._note_gave_up(fitted, poses)
            if unlearned:
                fitted_costs = fitted_costs + self._first_error_costs(fitted, poses, statuses)
                costs[[i for i in range(1, len(costs)) if i not in order]] = np.inf
            for i, motion, cost in zip(order, fitted, fitted_costs):
                pool[i], costs[i] = motion, cost
        best = int(np.argmin(costs))
        best_motion, best_cost = pool[best], float(costs[best])
        # Gauss-Newton from the best start at its frequency (templates at another frequency only
        # compete as they are).
        start = best_motion if not best_motion.is_zero() else candidates[1]
        refined, refined_cost = self._refine(start, poses, statuses)
        if refined is not None and s.ramp_midpoint == "plan":
            # Refined with the ramp crossfaded linearly (its probes are not solved half-way): ranked
            # with the fitted candidates with it solved.
            refined_cost = float(self._costs([refined], poses, statuses, budget=True, ramped=True)[0][0])
        if refined is not None and unlearned:
            refined_cost += float(self._first_error_costs([refined], poses, statuses)[0])
        if refined is not None and refined_cost < best_cost:
            best_motion, best_cost = refined, refined_cost
        best_motion, _scale = fit_envelope(best_motion, self.device, s.headroom, tolerance=s.plant_tolerance)
        final_cost, final_vel = self._costs([best_motion], poses, statuses, ramped=True)
        if self.current.is_zero() and math.isfinite(float(final_cost[0])):
            gentle = self._gentle(best_motion, poses)
            if gentle is not best_motion:
                self._gentle_full = (gentle.key, best_motion)
                best_motion = gentle
                final_cost, final_vel = self._costs([best_motion], poses, statuses, ramped=True)
        if unlearned and best_motion.key != self.current.key:
            final_cost = final_cost + self._first_error_costs([best_motion], poses, statuses)
        if (s.teach_amplitude < 1.0 and self.switches == 0 and not best_motion.is_zero()
                and math.isfinite(float(final_cost[0]))):
            # The task's first motion: its quiet copy first (MpcSettings.teach_amplitude).
            quiet = best_motion.scaled(s.teach_amplitude)
            quiet_cost, quiet_vel = self._costs([quiet], poses, statuses, ramped=True)
            # The quiet copy keeps contact where the motion does (the contact margin's use scales with
            # the amplitude); where the solver gave up on it (a part in stick-slip) it is predicted at
            # rest: it moves the parts little, and it is played to teach the feedback, not to move them.
            gave_up = self._memo[quiet.key][3]
            if math.isfinite(float(quiet_cost[0])) or gave_up:
                self._teach = (quiet.key, best_motion, t_s + s.teach_s)
                return self._switch(t_s, poses, quiet, quiet_vel[0])
        if not math.isfinite(float(final_cost[0])):
            if not math.isfinite(float(current_cost[0])):  # nothing safe found: stop the plate
                rest = PlateMotion.zero(self.current.frequency_hz, name="rest")
                return self._switch(t_s, poses, rest, np.zeros((len(self.goals), 3)))
            return self._switch(t_s, poses, self.current, current_vel[0], keep=True)
        if dwelt and self._better(float(final_cost[0]), float(current_cost[0]), poses, statuses):
            return self._switch(t_s, poses, best_motion, final_vel[0])
        return self._switch(t_s, poses, self.current, current_vel[0], keep=True)

    def _taught(self, t_s: float, poses: np.ndarray, statuses: list[PartStatus], current_cost: np.ndarray,
                current_vel: np.ndarray):
        """The first motion's quiet copy is playing (``MpcSettings.teach_amplitude``): kept for
        ``teach_s`` (predicted at rest where the solver gives up on it), then the motion at full
        amplitude (the feedback has learned the plant in its current directions). False: neither
        (the quiet copy loses a part's contact or leaves the region, or the full motion is not safe
        any more): plan as usual."""
        _key, full, until = self._teach
        if t_s < until - 1e-9:
            if math.isfinite(float(current_cost[0])) or self._memo[self.current.key][3]:   # or gave up on
                return self._switch(t_s, poses, self.current, current_vel[0], keep=True)
            self._teach = None
            return False
        self._teach = None
        cost, vel = self._costs([full], poses, statuses, ramped=True)
        if not math.isfinite(float(cost[0])):
            return False
        return self._switch(t_s, poses, full, vel[0])

    def _hold_playing(self, poses: np.ndarray) -> None:
        """The motion playing at these poses: solved (PLANNER_SOLVER), and where the solver gave up on
        it ("not converged" at some commanded part, contact kept at the others) within
        ``hold_gave_up_m`` / ``hold_gave_up_rad`` of every commanded part's pose where it last
        converged, its model velocities are that last prediction: a stick-slip cycle the solver's
        caps cut short near a pose where the motion worked is no reason to switch away from it
        (measured: the bracket's slow benchmark scenes; docs/planner.md). Contact lost is never held."""
        s = self.settings
        if self.current.is_zero():
            self._held = None
            return
        vel, ok = self._velocities([self.current], poses)
        key, G = self.current.key, len(self.goals)
        cmd = np.array([poses[g.index] for g in self.goals])
        if ok[0]:
            self._held = (key, cmd.copy(), vel[0].copy())
            return
        held, gave_up = self._held, self._memo[key][3]
        if not (gave_up and held is not None and held[0] == key and s.hold_gave_up_m > 0):
            return
        oriented = np.array([g.theta_rad is not None for g in self.goals])
        if _poses_near(cmd, held[1], oriented, s.hold_gave_up_m, s.hold_gave_up_rad):
            v = vel[0].copy()
            v[:G] = held[2][:G]
            self._memo[key] = (v, True, False, False)
            self._held_at = self._memo_poses
            self.held_predictions += 1

    def _suspects(self, motions: Sequence[PlateMotion], poses: np.ndarray) -> frozenset:
        """The keys of ``motions`` to solve on the give-up budget (``gave_up_max_steps_per_period``): those
        whose name the solver gave up on at full caps, each part it gave up at within ``gave_up_near_m`` /
        ``hold_gave_up_rad`` of its pose then."""
        s = self.settings
        if not (s.gave_up_max_steps_per_period or s.gave_up_max_periods) or not self._gave_up_at:
            return frozenset()
        cmd = np.array([poses[g.index] for g in self.goals])
        oriented = np.array([g.theta_rad is not None for g in self.goals])
        out = set()
        for m in motions:
            hit = self._gave_up_at.get(m.name)
            if hit is None:
                continue
            rows, at = hit
            if _poses_near(cmd[rows], at, oriented[rows], s.gave_up_near_m, s.hold_gave_up_rad):
                out.add(m.key)
        return frozenset(out)

    def _note_gave_up(self, motions: Sequence[PlateMotion], poses: np.ndarray) -> None:
        """After solving fitted candidates: remember where the solver gave up on one at full caps (a row
        given up on within the budget is not re-recorded, so the budget cannot follow the part along its
        path), forget one that converged or lost contact."""
        s = self.settings
        if not (s.gave_up_max_steps_per_period or s.gave_up_max_periods):
            return
        for m in motions:
            hit = self._memo.get(m.key)
            if hit is None or m.is_zero():
                continue
            rows = self._rows_gave_up.get(m.key)
            if hit[3] and not hit[2] and rows is not None and rows.any():
                self._gave_up_at[m.name] = (rows, np.array([poses[g.index] for g in self.goals])[rows])
            elif not hit[3]:
                self._gave_up_at.pop(m.name, None)

    def _remember_playing(self, motion: PlateMotion, poses: np.ndarray) -> None:
        """The motion about to play, solved at these poses (not held): where it last converged."""
        here = self._pose_key(poses)
        hit = self._memo.get(motion.key) if here == self._memo_poses else None
        if motion.is_zero() or hit is None or not hit[1] or self._held_at == here:
            return
        self._held = (motion.key, np.array([poses[g.index] for g in self.goals]), hit[0].copy())

    def _close(self, st: PartStatus) -> bool:
        """Whether a part is close enough to its goal that the strong templates (STRONG_TEMPLATES)
        would throw it and its neighbours more than they help: within ``near_m`` and, for a goal
        angle, within ``strong_turn_from_rad``."""
        s = self.settings
        return st.position_error_m <= s.near_m and (
            st.angle_error_rad is None or abs(st.angle_error_rad) <= s.strong_turn_from_rad)

    def _better(self, new: float, current: float, poses: np.ndarray, statuses: list[PartStatus]) -> bool:
        """Worth a switch: the cost falls by ``switch_gain`` of the current one, or the progress over
        the plate at rest (its cost minus the motion's) grows by that fraction of the new progress.
        The second rule matters when every motion is weak: a bracket at its goal position 53 deg off
        kept a sink that did nothing for 20 s, as a turn lowered the cost by only 9 %."""
        g = self.settings.switch_gain
        if new < (1.0 - g) * current:
            return True
        rest = float(self._costs([PlateMotion.zero(self.current.frequency_hz, name="rest")], poses, statuses,
                                 ramped=True)[0][0])
        if not (math.isfinite(rest) and math.isfinite(current)):
            return False
        gained, had = rest - new, max(rest - current, 0.0)
        return gained > 0 and gained - had > g * gained

    def _spin(self) -> PlateMotion:
        """The spin about the centre (``spin_motion``) fitted into the envelope: the spin and pivot
        templates' design."""
        return self._fitted(spin_motion(self.settings))

    def _fitted(self, motion: PlateMotion) -> PlateMotion:
        return self._fitted_many([motion])[0]

    def _fitted_many(self, motions: Sequence[PlateMotion]) -> list[PlateMotion]:
        """``motions`` fitted into the envelope with the planner's headroom and plant tolerance (cached:
        the sink at a goal recurs every step; the others fitted together)."""
        s = self.settings
        out = {m.key: self._fits.get(m.key) for m in motions}   # the hits taken before the cache may be cleared
        new = {m.key: m for m in motions if out[m.key] is None}
        if new:
            if len(self._fits) + len(new) > 256:
                self._fits.clear()
            for key, (fitted, _) in zip(new, fit_envelope_many(list(new.values()), self.device, s.headroom,
                                                               tolerance=s.plant_tolerance)):
                self._fits[key] = out[key] = fitted
        return [out[m.key] for m in motions]

    def _update_focus(self, t_s: float, statuses: list[PartStatus]) -> None:
        s = self.settings
        metric = sum(0.0 if st.within else st.position_error_m
                     + s.angle_weight_m_per_rad * abs(st.angle_error_rad or 0.0)
                     for st in statuses if math.isfinite(st.position_error_m))
        self.progress.append((t_s, metric))
        while len(self.progress) > 2 and t_s - self.progress[1][0] >= s.stall_s:
            self.progress.pop(0)
        if self.focus is not None:
            k = next(i for i, g in enumerate(self.goals) if g.index == self.focus)
            if t_s - self.focus_since >= s.focus_s or statuses[k].within:
                self.focus, self.progress = None, [(t_s, metric)]
            return
        t0, m0 = self.progress[0]
        unfinished = [(st.position_error_m / g.position_tol_m + (abs(st.angle_error_rad) / g.angle_tol_rad
                                                                if st.angle_error_rad is not None else 0.0), g.index)
                      for g, st in zip(self.goals, statuses) if not st.within and math.isfinite(st.position_error_m)]
        if len(self.goals) > 1 and unfinished and t_s - t0 >= s.stall_s and metric > 0.9 * m0:
            self.focus, self.focus_since = max(unfinished)[1], t_s

    def _gentle(self, motion: PlateMotion, poses: np.ndarray) -> PlateMotion:
        """``motion`` (from rest) scaled down to the largest of ``gentle_amplitudes`` at which no
        commanded part whose velocity scale is not estimated yet is predicted faster than
        ``gentle_speed_mps``, contact kept (all amplitudes in one batched call); the smallest valid
        one when none is that slow; ``motion`` itself when every part's scale is known."""
        s, G = self.settings, len(self.goals)
        fresh = [k for k, g in enumerate(self.goals)
                 if not self.state[g.index].estimated and g.index not in self.unseen]
        if s.gentle_speed_mps <= 0 or motion.is_zero() or not fresh:
            return motion
        amps = sorted(set(s.gentle_amplitudes) | {1.0}, reverse=True)
        trials = [motion if a == 1.0 else motion.scaled(a) for a in amps]
        v, ok = self._velocities(trials, poses)
        speed = np.hypot(v[:, :G, 0], v[:, :G, 1])[:, fresh].max(axis=1)
        valid = [i for i in range(len(trials)) if ok[i]]
        if not valid:
            return motion
        slow = [i for i in valid if speed[i] <= s.gentle_speed_mps]
        return trials[slow[0] if slow else valid[-1]]

    def _first_error_costs(self, motions, poses: np.ndarray, statuses: list[PartStatus]) -> np.ndarray:
        """Per motion (M,), the cost of its first error: the rms spread of each commanded part's
        predicted displacement over the horizon across the plant tolerance's uncorrected plants
        (``uncorrected_motions``), weighted as the part's waypoint and by ``first_error_weight``, in the
        cost's units. All draws of all motions in one batched call per part model."""
        s, G = self.settings, len(self.goals)
        moving = [m for m, motion in enumerate(motions) if not motion.is_zero()]
        out = np.zeros(len(motions))
        if not moving:
            return out
        scales = np.array([self.state[g.index].scale for g in self.goals])
        span = s.horizon_s - 0.5 * min(s.ramp_s, s.horizon_s)
        var = np.zeros((len(moving), G))
        if s.plant_tolerance is not None and self.switches < s.unlearned_motions:
            draws = [d for m in moving for d in uncorrected_motions(motions[m], self.device, s.plant_tolerance)]
            v, _ok = self._velocities(draws, poses)
            d = v[:, :G, :2].reshape(len(moving), s.plant_tolerance.samples, G, 2)
            d = d * (span * scales)[None, None, :, None]
            var += np.mean(np.sum((d - d.mean(axis=1, keepdims=True)) ** 2, axis=3), axis=1)
        for part, js in self._groups:
            # Friction unknown: the displacements at the ends of the prior range, as a uniform spread
            # (one call per end for the parts of one model).
            ks = [j for j in js if j < G and not self.state[self._rows[j]].estimated
                  and self._rows[j] not in self.unseen]
            if not ks:
                continue
            cfg = poses[[self._rows[j] for j in ks], :_dim(part)]
            ends = [predict_velocities([motions[m] for m in moving], _with_friction(part, f), cfg)[0][..., :2]
                    for f in s.friction_prior]
            var[:, ks] += np.sum(np.nan_to_num(ends[1] - ends[0]) ** 2, axis=2) * (span * scales[ks]) ** 2 / 12.0
        _way, weight = self._waypoints(poses, statuses)
        out[moving] = np.sum((s.first_error_weight * weight[None]) ** 2 * var / s.max_speed_mps ** 2, axis=1)
        return out

    def _plant_factor(self, motion: PlateMotion, t_s: float) -> np.ndarray:
        """Per goal (G, 3), the fraction of the model velocity ``motion`` plays over the replanning
        period from ``t_s``: the uncorrected plants' mean for an unlearned motion until the feedback's
        first estimate, decaying to 1 as the feedback corrects it; 1 for every other motion."""
        hit = self._first_error.get(motion.key)
        if hit is None:
            return np.ones((len(self.goals), 3))
        s = self.settings
        ratio, t0 = hit
        since = t_s + 0.5 * s.replan_period_s - t0
        fade = 1.0 if since < s.feedback_first_estimate_s else math.exp(
            -(since - s.feedback_first_estimate_s) / s.feedback_decay_s)
        return 1.0 - (1.0 - ratio) * fade

    def _learn_first_error(self, motion: PlateMotion, poses: np.ndarray, velocity: np.ndarray, t_s: float) -> None:
        """A new motion the feedback has not learned the plant for (the first ``unlearned_motions``
        of the task): the mean velocity over the plant tolerance's uncorrected plants against the
        model's, per goal (translation and rotation apart), from one batched solver call."""
        s = self.settings
        if motion.is_zero() or s.plant_tolerance is None or self.switches > s.unlearned_motions:
            return
        G = len(self.goals)
        v, ok = self._velocities(uncorrected_motions(motion, self.device, s.plant_tolerance), poses)
        if not ok.any():
            return
        mean = v[ok, :G].mean(axis=0)
        ratio = np.ones((G, 3))
        for cols in (slice(0, 2), slice(2, 3)):
            den = np.sum(velocity[:, cols] ** 2, axis=1)
            num = np.sum(mean[:, cols] * velocity[:, cols], axis=1)
            ratio[:, cols] = np.where(den > 1e-12, np.clip(num / np.maximum(den, 1e-12), 0.0, 1.5), 1.0)[:, None]
        self._first_error[motion.key] = (ratio, t_s)

    def _switch(self, t_s, poses, motion, velocity, keep: bool = False, middle: bool = True) -> PlateMotion | None:
        """Play ``motion`` from ``t_s`` (``keep``: the motion playing goes on) with its model velocities
        ``velocity`` (G, 3): the segment the next estimate compares with, and ``last_prediction``.
        ``middle`` (and ``ramp_midpoint``): the ramp of a new motion predicted with the model half-way
        through it; the plate stopped from outside (``plate_stopped``) is not solved."""
        changed = motion.key != self.current.key
        velocity = np.nan_to_num(velocity)
        previous = velocity if keep else self._v_current * self._plant_factor(self.current, t_s)
        if changed:
            self.switches += 1
            self.t_switch = t_s
            self._learn_first_error(motion, poses, velocity, t_s)
        mid = None
        if changed and middle and self.settings.ramp_midpoint != "off":
            # Half-way, the plant errors of both motions play at half weight.
            mid = (self._middles([motion], poses, velocity[None])[0]
                   * 0.5 * (self._plant_factor(self.current, t_s) + self._plant_factor(motion, t_s)))
        velocity = velocity * self._plant_factor(motion, t_s)
        if keep:
            previous = velocity
        self._remember_playing(motion, poses)
        self.current = motion
        self.segment = _Segment(t_s, poses.copy(), velocity, previous, motion.key, frozenset(self.unseen), mid)
        scales = self._axis_scales()
        self.last_prediction = {"t_s": t_s, "motion": motion, "poses": poses.copy(), "switched": changed,
                                "velocity": velocity * scales, "previous": previous * scales,
                                "middle": None if mid is None else mid * scales,
                                "ramp_s": self.settings.ramp_s}
        return motion if changed else None

    def _pivot(self, goal: PartGoal, pose: np.ndarray) -> np.ndarray | None:
        """The pivot (x, y) a rigid part at ``pose`` is turned about (``MpcSettings.pivot_from_rad``):
        None when off, for a point part or no goal angle, nearer its goal angle than that, a velocity
        scale not estimated yet or under ``pivot_min_scale``, or a pivot beyond ``region_radius_m`` of
        the centre."""
        s = self.settings
        if not (s.pivot_from_rad > 0 and goal.theta_rad is not None
                and isinstance(self.parts[goal.index], RigidPart) and np.all(np.isfinite(pose))):
            return None
        a = -float(_wrap(pose[2] - goal.theta_rad, self.symmetry[goal.index]))
        st = self.state[goal.index]
        slow = s.pivot_min_scale > 0 and not (st.estimated and st.scale >= s.pivot_min_scale)
        if abs(a) < s.pivot_from_rad or slow:   # slow: high friction (or not known yet) turns badly off the part
            return None
        c = pivot_point(pose, goal, a)
        return c if c is not None and float(np.hypot(*c)) <= s.region_radius_m else None

    def _pair_rotations(self, poses: np.ndarray, statuses: list[PartStatus]) -> list[PlateMotion]:
        """``MpcSettings.swap_from_rad``: for every two unfinished, seen parts whose segment has to turn
        at least that much, the rotation design moved to the fixed point of that turn (``pair_rotation``,
        within ``region_radius_m`` of the centre), both ways."""
        s = self.settings
        if not s.swap_from_rad > 0:
            return []
        moving = [g for g, st in zip(self.goals, statuses)
                  if not st.within and g.index not in self.unseen and np.all(np.isfinite(poses[g.index]))]
        out = []
        for i, a in enumerate(moving):
            for b in moving[i + 1:]:
                c, angle = pair_rotation(poses[a.index], poses[b.index], (a.x_m, a.y_m), (b.x_m, b.y_m))
                if c is None or abs(angle) < s.swap_from_rad or float(np.hypot(*c)) > s.region_radius_m:
                    continue
                out += both_ways(self._base("rotation"), c, "swap", f"{a.index},{b.index}")
        return out

    def _integrate_aims(self, t_s: float, poses: np.ndarray) -> None:
        """Integral action (``integral_per_s``; ``integral_parts``, at most ``integral_max_parts``
        commanded): each frame, the aim of a part within ``integral_within_m`` of its goal (once it has
        been so near for ``integral_after_s``) moves by the gain times its position error times the
        frame's interval, within ``integral_max_m``."""
        s = self.settings
        if s.integral_per_s <= 0 or len(self.goals) > s.integral_max_parts:
            return
        for g in self.goals:
            st = self.state[g.index]
            if s.integral_parts == "point" and isinstance(self.parts[g.index], RigidPart):
                continue
            p = poses[g.index]
            ex, ey = g.x_m - float(p[0]), g.y_m - float(p[1])
            last, st.aim_t = st.aim_t, t_s
            if not (math.isfinite(ex) and math.isfinite(ey)) or math.hypot(ex, ey) >= s.integral_within_m:
                continue
            if st.near_since is None:
                st.near_since = t_s
            if last is None or t_s - st.near_since < s.integral_after_s:
                continue
            ax = st.aim[0] + s.integral_per_s * ex * (t_s - last)
            ay = st.aim[1] + s.integral_per_s * ey * (t_s - last)
            n = math.hypot(ax, ay)
            f = 1.0 if n <= s.integral_max_m else s.integral_max_m / n
            st.aim = (ax * f, ay * f)

    def _aimed(self, g: PartGoal) -> PartGoal:
        """The goal the planner aims the part of ``g`` at: ``g`` moved by its integral action's offset."""
        ax, ay = self.state[g.index].aim
        if ax == 0.0 and ay == 0.0:
            return g
        return dataclasses.replace(g, x_m=g.x_m + ax, y_m=g.y_m + ay)

    def _waypoints(self, poses: np.ndarray, statuses: list[PartStatus]) -> tuple[np.ndarray, np.ndarray]:
        """Per goal: the target configuration after the horizon (G, 3) and the weights (G,)."""
        s, H = self.settings, self.settings.horizon_s
        way = np.zeros((len(self.goals), 3))
        weight = np.ones(len(self.goals))
        approach = self.approach_per_s()
        for k, (g, st) in enumerate(zip(self.goals, statuses)):
            g = self._aimed(g)
            p = poses[g.index]
            e = np.array([g.x_m - p[0], g.y_m - p[1]])
            d = float(np.hypot(*e))
            step = min(1.0, approach * H, s.max_speed_mps * H / d) if d > 0 else 0.0
            way[k, :2] = p[:2] + step * e
            if g.theta_rad is not None:
                a = -float(_wrap(p[2] - g.theta_rad, self.symmetry[g.index]))
                lim = min(s.max_turn_radps * H, approach * H * abs(a))
                turn = float(np.clip(a, -lim, lim))
                way[k, 2] = p[2] + turn
                c = self._pivot(g, p)
                if c is not None:   # turned about the pivot: the turn and the way home at once
                    co, si = math.cos(turn), math.sin(turn)
                    r = p[:2] - c
                    way[k, :2] = c + np.array([co * r[0] - si * r[1], si * r[0] + co * r[1]])
            else:
                way[k, 2] = p[2]
            tr = self.state[g.index]
            out = st.position_error_m > s.hold_release * g.position_tol_m or (
                st.angle_error_rad is not None and abs(st.angle_error_rad) > s.hold_release * g.angle_tol_rad)
            tr.holding = st.within or (tr.holding and not out)
            if tr.holding:  # asked to stay where it is; one slipped out (not beyond the release) back in
                if st.within:
                    way[k] = self._held_waypoint(g, p)
                weight[k] = s.hold_weight
            if self.focus is not None and g.index != self.focus and not tr.holding:
                # Focus lowers the weight of the other unfinished parts; of a held one only in the
                # endgame (focus_held): far from the focused part's goal, a motion that turned the
                # focused bracket threw a washer off its goal at 13 mm/s (benchmark scene 7 of 3 parts).
                weight[k] *= s.focus_others
            if (tr.holding and self.focus is not None and g.index != self.focus and s.focus_held < 1.0
                    and self._focus_near(statuses)):
                weight[k] *= s.focus_held
            if g.index in self.unseen:  # not seen: asked to stay where it was last seen
                way[k] = self.last_pose[g.index]
                weight[k] = s.hold_weight
        return way, weight

    def _held_waypoint(self, g: PartGoal, p: np.ndarray) -> np.ndarray:
        """Where a held part within tolerance is asked to stay (``hold_within``): its pose, its
        position and angle errors cut to that fraction of its tolerances."""
        f = self.settings.hold_within
        way = np.array(p, dtype=float)
        if f is None:
            return way
        e = way[:2] - (g.x_m, g.y_m)
        d, r = float(np.hypot(*e)), f * g.position_tol_m
        if d > r:
            way[:2] = (g.x_m, g.y_m) + e * (r / d)
        if g.theta_rad is not None and math.isfinite(way[2]):
            a = float(_wrap(way[2] - g.theta_rad, self.symmetry[g.index]))
            lim = f * g.angle_tol_rad
            way[2] -= a - float(np.clip(a, -lim, lim))
        return way

    def _focus_near(self, statuses: list[PartStatus]) -> bool:
        """The focused part is within ``near_m`` of its goal position (only its fine pose is left)."""
        k = next(i for i, g in enumerate(self.goals) if g.index == self.focus)
        return statuses[k].position_error_m <= self.settings.near_m

    def _angle_weights(self, statuses: list[PartStatus], poses: np.ndarray) -> np.ndarray:
        """Per goal, the weight of an angle error (m/rad): full within ``angle_from_m`` of the goal,
        falling as angle_from_m / distance beyond it; full for a part turned about its pivot
        (``MpcSettings.pivot_from_rad``)."""
        s = self.settings
        d = np.array([st.position_error_m if math.isfinite(st.position_error_m) else 0.0 for st in statuses])
        w = s.angle_weight_m_per_rad * np.minimum(1.0, s.angle_from_m / np.maximum(d, 1e-9))
        if s.pivot_from_rad > 0:
            for k, g in enumerate(self.goals):
                if self._pivot(g, poses[g.index]) is not None:
                    w[k] = s.angle_weight_m_per_rad
        return w

    def _middles(self, motions: Sequence[PlateMotion], poses: np.ndarray, ends: np.ndarray) -> np.ndarray | None:
        """Per motion (M, G, 3), the commanded parts' model velocities half-way through the ramp from
        the motion playing to it (``crossfade`` at 0.5, solved in one batched call; the motion
        playing itself: its own velocities ``ends`` (M, R, 3)); None with ``ramp_midpoint`` "off".
        Where contact is lost half-way, the mean of the two ends (the linear crossfade)."""
        if self.settings.ramp_midpoint == "off":
            return None
        G = len(self.goals)
        out = np.array(ends[:, :G], dtype=float)   # the motion playing: no ramp
        todo = [i for i, m in enumerate(motions) if m.key != self.current.key]
        if todo:
            v_cur = getattr(self, "_v_current", None)
            v_cur = self._current_velocity(poses) if v_cur is None else v_cur
            v, ok = self._velocities([crossfade(self.current, motions[i], 0.5) for i in todo], poses)
            out[todo] = np.where(ok[:, None, None], v[:, :G], 0.5 * (v_cur[None] + out[todo]))
        return out

    def _costs(self, motions: Sequence[PlateMotion], poses: np.ndarray, statuses: list[PartStatus],
               budget: bool = False, ramped: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Cost (M,) (inf where contact is lost at a commanded part) and model velocities (M, G, 3);
        ``budget``: see :meth:`_velocities`; ``ramped``: with ``ramp_midpoint`` "plan", each motion's
        ramp predicted with the model half-way through it (:meth:`_middles`)."""
        mids = None
        if ramped and self.settings.ramp_midpoint == "plan":
            mids = self._middles(motions, poses, self._velocities(motions, poses, budget)[0])
        r, vel, ok = self._residuals(motions, poses, statuses, budget, mids)
        cost = np.sum(r ** 2, axis=1)
        if self.settings.stop_on_way:
            cost = np.minimum(cost, self._finish_costs(motions, vel, mids, poses))
        cost[~ok] = np.inf
        # Never drive a part out of the working disc: a predicted position beyond it (and beyond
        # where the part already is) rules the candidate out.
        cur = np.array([poses[g.index, :2] for g in self.goals])
        r_now = np.hypot(cur[:, 0], cur[:, 1])
        scales = np.array([self.state[g.index].scale for g in self.goals])
        pred = cur[None] + scales[None, :, None] * self._horizon_displacement(vel, mids)[..., :2]
        r_pred = np.hypot(pred[..., 0], pred[..., 1])
        out = np.any(r_pred > np.maximum(r_now, self.settings.region_radius_m)[None], axis=1)
        cost[out] = np.inf
        return cost, vel

    def _finish_costs(self, motions: Sequence[PlateMotion], vel: np.ndarray, mids: np.ndarray | None,
                      poses: np.ndarray) -> np.ndarray:
        """Per motion (M,), the cost of stopping on its way (``stop_on_way``; inf where no stop finishes):
        at the first frame within the horizon from which the ramp down would leave every commanded part
        within ``stop_within`` of its tolerances (judged as the stop ahead judges it: the predicted pose
        plus the velocity then over half the ramp) for ``stop_on_way_frames`` frames in a row (the motion
        playing: ``stop_on_way_playing_frames``), the landing's distance from the goals (angles weighed
        by ``angle_weight_m_per_rad``), in the units of the horizon's cost. The plate at rest then holds
        every part."""
        s = self.settings
        M = vel.shape[0]
        out = np.full(M, np.inf)
        cur = poses[self._rows[:len(self.goals)]]   # the commanded rows come first
        if not np.all(np.isfinite(cur[:, :2])):
            return out
        goal, oriented, pos_tol, ang_tol, period = self._goal_arrays
        pos_tol, ang_tol = s.stop_within * pos_tol, s.stop_within * ang_tol
        turned = oriented & np.isfinite(cur[:, 2])
        v_cur = getattr(self, "_v_current", None)
        v_cur = np.zeros_like(cur) if v_cur is None else v_cur
        w, a = _frame_weights(s.horizon_s, s.stop_on_way_step_s, s.ramp_s, mids is not None)
        disp = v_cur * w[:, 0] + vel * w[:, 2]
        if mids is not None:
            disp += mids * w[:, 1]
        disp += (v_cur + a * (vel - v_cur)) * (0.5 * s.ramp_s)        # the ramp down's carry
        land = cur + self._axis_scales(motions) * disp                   # (T, M, G, 3)
        d = np.hypot(land[..., 0] - goal[:, 0], land[..., 1] - goal[:, 1])
        ang = np.where(turned, _wrap(land[..., 2] - goal[:, 2], period), 0.0)
        ang = np.nan_to_num(ang, nan=np.inf)
        ok = np.all((d <= pos_tol) & (np.abs(ang) <= ang_tol), axis=2)   # (T, M)
        if not ok.any():
            return out
        c = np.concatenate([np.zeros((1, M), int), np.cumsum(ok, axis=0)])
        ok = np.zeros_like(ok)
        playing = np.array([m.key == self.current.key for m in motions])
        for k, which in ((s.stop_on_way_frames, ~playing), (s.stop_on_way_playing_frames, playing)):
            if which.any():   # within for k frames in a row, marked at the last of them
                ok[k - 1:, which] = ((c[k:] - c[:-k]) == k)[:, which]
        hit = ok.any(axis=0)
        if hit.any():
            j = np.argmax(ok, axis=0)[hit]
            m = np.flatnonzero(hit)
            out[hit] = np.sum(d[j, m] ** 2 + (s.angle_weight_m_per_rad * ang[j, m]) ** 2, axis=1) / s.max_speed_mps ** 2
        return out

    def _horizon_displacement(self, vel: np.ndarray, mids: np.ndarray | None) -> np.ndarray:
        """Per motion and goal (M, G, 3), the unscaled displacement over the horizon after a switch
        from the motion playing (``_v_current``; none yet: at rest) to each motion of model
        velocities ``vel`` (M, G, 3), through the generator's ramp (``ramp_weights``; with ``mids``,
        the velocities half-way through it)."""
        s = self.settings
        v_cur = getattr(self, "_v_current", None)
        v_cur = np.zeros(vel.shape[1:]) if v_cur is None else v_cur
        w_old, w_mid, w_new = ramp_weights(s.horizon_s, s.ramp_s, mids is not None)
        disp = v_cur[None] * w_old + vel * w_new
        return disp if mids is None else disp + mids * w_mid

    def _residuals(self, motions, poses, statuses, budget: bool = False, mids: np.ndarray | None = None):
        """Residuals (M, R), model velocities (M, G, 3) and validity (M,) of ``motions``: the
        predicted poses over the horizon against the waypoints, and the collisions; ``mids``
        (M, G, 3): the velocities half-way through each motion's ramp (:meth:`_middles`)."""
        vel_all, ok = self._velocities(motions, poses, budget)
        return self._residuals_of(motions, vel_all, ok, poses, statuses, mids)

    def _residuals_of(self, motions, vel_all: np.ndarray, ok: np.ndarray, poses, statuses,
                      mids: np.ndarray | None = None):
        """:meth:`_residuals` from the solved rows' model velocities ``vel_all`` (M, R, 3) and
        validity ``ok`` (M,)."""
        s, H = self.settings, self.settings.horizon_s
        M, G = len(motions), len(self.goals)
        vel = vel_all[:, :G]
        scales = self._axis_scales(motions)
        way, weight = self._waypoints(poses, statuses)
        cur = np.array([poses[g.index] for g in self.goals])
        r = min(s.ramp_s, H)
        pred = cur[None] + scales * self._horizon_displacement(vel, mids)  # (M, G, 3)
        res_xy = (pred[..., :2] - way[None, :, :2]) * weight[None, :, None]
        oriented = np.array([g.theta_rad is not None for g in self.goals], float)
        res_th = ((pred[..., 2] - way[None, :, 2]) * self._angle_weights(statuses, poses)[None] * oriented[None]
                  * weight[None])
        parts = [res_xy.reshape(M, -1), res_th]
        # Collisions between predicted positions (commanded parts, and the others if asked).
        idx = [g.index for g in self.goals]
        others = [j for j, i in enumerate(self._others) if np.all(np.isfinite(poses[i, :2]))]
        # The others where the candidate takes them (their own friction unknown: the model's).
        pred_others = (poses[[self._others[j] for j in others], :2][None]
                       + vel_all[:, [G + j for j in others], :2] * (H - 0.5 * r))
        others = [self._others[j] for j in others]
        centres = np.concatenate([pred[..., :2], pred_others], axis=1)
        radii = np.concatenate([self.radius[idx], self.radius[others]])
        ia, ib = _pairs(centres.shape[1], G)
        if ia.size:
            diff = centres[:, ia] - centres[:, ib]
            d = np.hypot(diff[..., 0], diff[..., 1])
            parts.append(np.maximum(0.0, (radii[ia] + radii[ib]) + s.clearance_m - d) * s.collision_weight)
        return np.concatenate(parts, axis=1) / s.max_speed_mps, vel, ok

    def _pose_key(self, poses: np.ndarray) -> bytes:
        """The solved rows' poses as the key of the per-step memo of model velocities."""
        return np.ascontiguousarray(poses[self._rows]).tobytes()

    def _velocities(self, motions, poses, budget: bool | frozenset = False) -> tuple[np.ndarray, np.ndarray]:
        """Model velocities (M, R, 3) (NaN as 0) of the solved rows (the commanded parts in goal order,
        then the kept-clear others) and validity (M,) at the commanded parts: one batched solver call
        per part model (and budget) for the motions not yet solved at these poses. Unseen rows:
        velocity 0. ``budget`` True: the motions not yet solved are solved on the probes' budget
        (``MpcSettings.probe_max_periods``, ``probe_max_steps_per_period``); a set of motion keys: those
        motions on the give-up budget (``gave_up_max_periods``, ``gave_up_max_steps_per_period``), the
        others without. A motion solved within a budget has the result it has without it, one not
        converged within it is solved again when asked without a budget."""
        pose_key = self._pose_key(poses)
        if pose_key != self._memo_poses:
            self._memo, self._memo_poses, self._rows_gave_up = {}, pose_key, {}
        keys = budget if isinstance(budget, frozenset) else frozenset()   # on the give-up budget
        probe = self._probe_solver() if budget is True else None
        new: dict[bytes, PlateMotion] = {}
        for motion in motions:
            hit = self._memo.get(motion.key)
            budgeted_now = probe is not None or motion.key in keys
            if hit is None or (not budgeted_now and hit[2] and not hit[1]):
                new.setdefault(motion.key, motion)
        if new:
            on = [m for m in new.values() if m.key in keys]
            off = [m for m in new.values() if m.key not in keys]
            for todo, settings in ((off, probe), (on, self._gave_up_solver() if on else None)):
                if todo:
                    self._solve_rows(todo, poses, settings)
        R = len(self._rows)
        vel = np.array([self._memo[m.key][0] for m in motions]).reshape(len(motions), R, 3)
        ok = np.array([self._memo[m.key][1] for m in motions], bool)
        return vel, ok

    def _solve_rows(self, todo: list[PlateMotion], poses: np.ndarray, settings) -> None:
        """Solve ``todo`` at the solved rows' poses (``settings`` None: PLANNER_SOLVER) into the memo."""
        G, rows = len(self.goals), self._rows
        R = len(rows)
        v_new = np.zeros((len(todo), R, 3))
        ok_new = np.ones(len(todo), bool)
        lost_new = np.zeros(len(todo), bool)   # some commanded row invalid for another reason than giving up
        rows_gave_up = np.zeros((len(todo), G), bool)
        for part, js in self._groups:
            dim, cfg, seen = self._group_configs(part, js, poses)
            v, valid, gave_up = predict_velocities(todo, part, cfg, settings, gave_up=True)
            v[:, ~seen] = 0.0
            v_new[:, js, :dim] = v
            commanded = np.array(js) < G
            ok_new &= valid[:, commanded].all(axis=1)
            lost_new |= (~valid[:, commanded] & ~gave_up[:, commanded]).any(axis=1)
            rows_gave_up[:, [j for j in js if j < G]] = gave_up[:, commanded]
        v_new = np.nan_to_num(v_new)
        for motion, v, o, lost, given_up in zip(todo, v_new, ok_new, lost_new, rows_gave_up):
            self._memo[motion.key] = (v, bool(o), settings is not None, not o and not lost)
            self._rows_gave_up[motion.key] = given_up

    def _group_configs(self, part, js: list[int], poses: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
        """A part model's solved rows ``js``: its dimension, their configurations (N, dim) (unseen
        rows at the origin) and which are seen (N,)."""
        dim = _dim(part)
        cfg = np.array([poses[self._rows[j], :dim] for j in js])
        seen = np.all(np.isfinite(cfg[:, :2]), axis=1)
        cfg[~seen] = 0.0
        return dim, cfg, seen

    def _probe_velocities(self, probes: list[PlateMotion], poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Model velocities (M, R, 3) and validity (M,) of the Gauss-Newton probes (``probes[0]`` the
        start, ``probes[1 + j]`` the start plus ``fd_step`` along input j of :func:`_to_vector`) on
        the probes' budget, with ``local_probes``: a point part feels the plate only at its own point
        r = (x, y), as the horizontal acceleration (p''x - alpha_z y, p''y + alpha_z x) and the normal
        one p''z + alpha_x y - alpha_y x (and their velocities, the same map), so its velocity's
        derivative along a rotation input is a combination of those along the translation inputs of
        the same harmonic and component (docs/planner.md, "Local probes"). Point rows are solved for
        the start and the translation probes only; rigid rows for every probe. A derived probe is
        valid where the probes it is made of are."""
        G, R, M = len(self.goals), len(self._rows), len(probes)
        start_vel, start_ok = self._velocities(probes[:1], poses, True)   # the start: the memo's, as without
        vel = np.zeros((M, R, 3))
        vel[0] = start_vel[0]
        ok = np.ones(M, bool)
        ok[0] = bool(start_ok[0])
        n = M - 1
        j_all = np.arange(n)
        axis = j_all % 6                  # inputs: 6 axes per harmonic, real parts, then imaginary ones
        translation = np.flatnonzero(axis < 3)
        ratio = float(_SCALE[3] / _SCALE[0])   # inputs are scaled per axis (_to_vector)
        settings = self._probe_solver()
        for part, js in self._groups:
            dim, cfg, seen = self._group_configs(part, js, poses)
            point = isinstance(part, PointPart)
            solve = translation if point else j_all
            v, valid = predict_velocities([probes[1 + j] for j in solve], part, cfg, settings)
            v = np.nan_to_num(v)
            v[:, ~seen] = 0.0
            commanded = np.array(js) < G
            rows_ok = np.zeros((n, len(js)), bool)
            rows_v = np.zeros((n, len(js), dim))
            rows_v[solve], rows_ok[solve] = v, valid
            if point:
                x, y = cfg[:, 0][:, None], cfg[:, 1][:, None]
                v0 = start_vel[0][js, :dim]
                for b in np.flatnonzero(axis == 0):   # p''x of each harmonic and component; p''y, p''z follow
                    dx, dy, dz = rows_v[b] - v0, rows_v[b + 1] - v0, rows_v[b + 2] - v0
                    rows_v[b + 3] = v0 + ratio * (y * dz)              # alpha_x: a_n gains alpha_x y
                    rows_v[b + 4] = v0 + ratio * (-x * dz)             # alpha_y: a_n loses alpha_y x
                    rows_v[b + 5] = v0 + ratio * (-y * dx + x * dy)    # alpha_z: a_h gains alpha_z (-y, x)
                    rows_ok[b + 3] = rows_ok[b + 4] = rows_ok[b + 2]
                    rows_ok[b + 5] = rows_ok[b] & rows_ok[b + 1]
            vel[1:, js, :dim] = rows_v
            ok[1:] &= rows_ok[:, commanded].all(axis=1)
        return vel, ok

    def _probe_solver(self):
        """The solver settings of the Gauss-Newton probes and trials (None: PLANNER_SOLVER's)."""
        s = self.settings
        if not (s.probe_max_periods or s.probe_max_steps_per_period):
            return None
        return budgeted(s.probe_max_periods, s.probe_max_steps_per_period)

    def _gave_up_solver(self):
        """The solver settings of fitted candidates the solver gave up on nearby (``_suspects``)."""
        s = self.settings
        return budgeted(s.gave_up_max_periods, s.gave_up_max_steps_per_period)

    def _refine(self, start: PlateMotion, poses, statuses) -> tuple[PlateMotion | None, float]:
        """Gauss-Newton steps from ``start``: finite-difference probes and line-search trials solved on
        the probes' budget (``_velocities(..., budget=True)``); a probe not converged within it gives
        no Jacobian column, a trial not converged within it is not taken."""
        s = self.settings
        freq = start.frequency_hz
        harmonics = self.harmonics
        v = _to_vector(start, harmonics)
        best_cost = float(self._costs([start], poses, statuses)[0][0])
        best = start
        n = v.size
        for _ in range(s.gauss_newton_steps):
            probes = [_to_motion(v, freq, harmonics)] + [_to_motion(v + s.fd_step * np.eye(n)[j], freq, harmonics)
                                                         for j in range(n)]
            if s.local_probes and self._point_groups:
                r, _vel, ok = self._residuals_of(probes, *self._probe_velocities(probes, poses), poses, statuses)
            else:
                r, _vel, ok = self._residuals(probes, poses, statuses, budget=True)
            if not ok[0]:
                break
            J = (r[1:] - r[0]).T / s.fd_step                    # (R, n)
            J[:, ~ok[1:]] = 0.0
            lam = 1e-3 * float(np.trace(J.T @ J)) / n + 1e-12
            dv = -np.linalg.solve(J.T @ J + lam * np.eye(n), J.T @ r[0])
            norm = float(np.linalg.norm(dv))
            if norm > s.max_change:
                dv *= s.max_change / norm
            floor = s.min_amplitude * float(np.linalg.norm(_to_vector(self._base("sink"), 1)))
            trials = []
            for a in (1.0, 0.5, 0.25):
                vt = v + a * dv
                norm_t = float(np.linalg.norm(vt))
                if 0 < norm_t < floor:
                    vt = vt * (floor / norm_t)
                trials.append(_to_motion(vt, freq, harmonics, name="mpc"))
            taken = None
            for batch in ([trials] if s.line_search == "best" else [[t] for t in trials]):
                fitted = [m for m, _ in fit_envelope_many(batch, self.device, s.headroom, tolerance=s.plant_tolerance)]
                costs, _ = self._costs(fitted, poses, statuses, budget=True)
                j = int(np.argmin(costs))
                if costs[j] < best_cost:
                    taken = fitted[j], float(costs[j])
                    break
            if taken is None:
                break
            best, best_cost = taken
            v = _to_vector(best, harmonics)
        return (best if best is not start else None), best_cost

    # ------------------------------------------------------------------ reporting
    def _worst(self, statuses) -> tuple[float, float | None]:
        d = [st.position_error_m for st in statuses if math.isfinite(st.position_error_m)]
        a = [abs(st.angle_error_rad) for st in statuses if st.angle_error_rad is not None]
        return (max(d) if d else math.nan), (max(a) if a else None)

    def _text(self, statuses) -> str:
        return f"{self.phase}: " + ", ".join(
            progress_bit(self.names[st.index], st.position_error_m, st.angle_error_rad, st.within)
            for st in statuses)

    def _end(self, statuses, failed: str | None, elapsed: float | None = None) -> MultiStep:
        d, a = self._worst(statuses)
        def one(st: PartStatus) -> str:
            a = "" if st.angle_error_rad is None else f" {math.degrees(abs(st.angle_error_rad)):.2f} deg"
            return f"{self.names[st.index]} {1e3 * st.position_error_m:.2f} mm{a}"

        text = (f"done in {elapsed:.1f} s: " + ", ".join(one(st) for st in statuses)) if failed is None \
            else f"failed: {failed}"
        stop = None
        if failed is None and not self.current.is_zero():
            # Done while a motion plays (every part settled within tolerance before the planner
            # stopped the plate): the plate at rest holds them there.
            stop = self.current = PlateMotion.zero(self.current.frequency_hz, name="rest")
        self.finished = MultiStep(stop, "failed" if failed else "done", failed is None, failed, d, a, text,
                                  tuple(statuses))
        return self.finished


__all__ = ["BASE_KINDS", "TEMPLATES", "TEMPLATE_BASES", "MpcSettings", "MultiStep", "MultiTask", "PartGoal",
           "PartStatus", "base_design", "base_kinds", "check_goals", "line_through", "moved", "part_radius_m",
           "progress_bit", "ramped_displacement", "template_motion"]
