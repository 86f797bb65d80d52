"""The interpretation register: every reading of an ambiguous passage of the paper, its default,
its alternatives and the config key that flips it (the report lists it)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class RegisterEntry:
    """One reading of an ambiguous passage of the paper."""

    topic: str
    paper_says: str
    default: str
    alternatives: str
    config_key: str


INTERPRETATION_REGISTER: tuple[RegisterEntry, ...] = (
    RegisterEntry(
        "Sign of B2", "B2 printed as [0 0 0 1 0]^T (minus signs lost in extraction)",
        "B2 = [0, 0, -1, 0, 0]^T: d(psi - psi_d)/dt = r - r_d (r_d = v kappa, the path's "
        "curvature previewed over the horizon; in the fixed frame the line is straight and "
        "r_d = 0)",
        "+1 (literal placement of a positive entry in the heading row)",
        "model.b2_heading_entry"),
    RegisterEntry(
        "Adaptive gain k_rep of the exponential law",
        "k_rep e^{alpha(1 - d/d0)} d/|d|^2, k_rep not given",
        "k_rep = H_i (the adaptive coefficient, so C3's distance gating carries over)",
        "a constant k_rep (planner.k_rep_constant)", "planner.k_rep_source"),
    RegisterEntry(
        "Two different 'alpha'", "alpha is both the APF step size and the exponent's slope",
        "two parameters: planner.step_size (step) and planner.alpha_e (exponent)",
        "-", "planner.step_size, planner.alpha_e"),
    RegisterEntry(
        "Step cap of the unnormalized rollout",
        "improved step is alpha*F without normalization",
        "each rollout step is capped at planner.step_max_m = 0.5 m (improved preset); without it "
        "the first step is alpha*|g - p|, i.e. metres, and explodes near an obstacle",
        "null: no cap (literal)", "planner.step_max_m"),
    RegisterEntry(
        "Minimum movement threshold",
        "'If F_total is too small, the system may be forced to push'",
        "a step shorter than planner.step_min_m is lengthened to step_min_m along F "
        "(along the goal direction when F = 0)",
        "0: off", "planner.step_min_m"),
    RegisterEntry(
        "Value of beta in H_i (improved)", "'use exp(beta (s - s0)^2) to adjust sensitivity', no value",
        "beta = 0.25 (wider longitudinal support than the baseline's beta = 1)",
        "any beta >= 0", "planner.beta"),
    RegisterEntry(
        "Distance in the repulsion laws", "rho = |p - p_obs|",
        "centre-to-centre distance, floored at planner.rho_floor_m so an obstacle at p gives a "
        "finite force (direction: away from the goal line's left normal when p = o)",
        "-", "planner.rho_floor_m"),
    RegisterEntry(
        "Obstacle positions inside the APF rollout",
        "the APF uses the obstacle list O, no time index inside the rollout",
        "current (measured) positions, held over the rollout; the MPC constraints still predict "
        "obstacle motion at constant velocity",
        "constant_velocity prediction (velocity-aware variant)", "planner.obstacle_prediction"),
    RegisterEntry(
        "Velocity/acceleration sensitivity coefficient",
        "introduction promises repulsion scaled by relative velocity; never defined",
        "off in baseline and improved; the velocity_aware preset scales repulsion by "
        "1 + gain * closing speed", "gain > 0", "planner.closing_speed_gain_s_per_m"),
    RegisterEntry(
        "What the lateral model's state is measured against",
        "Section 2: state [y, vy, psi - psi_d, r, delta] with d(psi - psi_d)/dt = r - r_d, "
        "r_d 'desired yaw rate (external disturbance)': the lateral error dynamics about a "
        "desired path (Rajamani, ch. 2-3)",
        "path: each step the state is the offset and heading error from a path built from the "
        "APF rollout (which path: the next entry), its curvature is previewed as r_d, the "
        "references are the model's equilibrium on it (r = r_d and the steering and sideslip "
        "that hold it: controller.path_state_reference), the stations follow the predicted "
        "speed, obstacles are projected to path coordinates; the prediction step stretches so "
        "the horizon covers controller.horizon_reach_m at low speed",
        "fixed: the state against the start-goal line (the earlier reading: the model's "
        "small-angle bound is left in 199 of 200 runs of the improved method); "
        "path_state_reference=zero (r and delta penalized about 0); horizon_reach_m=null (the "
        "horizon is Np Ts at any speed)",
        "controller.frame, controller.path_state_reference, controller.horizon_reach_m"),
    RegisterEntry(
        "The path the lateral MPC follows",
        "Section 3.1: the APF rollout is the MPC's reference, y_ref over the horizon, with "
        "psi_apf / omega_ref from it",
        "rollout: the rollout itself, each point at the time the vehicle would reach it (the "
        "polyline resampled at v dt per MPC step, headings bisecting its chords, curvature the "
        "heading's change; ended where the rollout folds back on itself, extended beyond its "
        "end); where it asks for more curvature than the vehicle has, that is counted as the "
        "APF's demand (path_beyond_limit) and never repaired",
        "pursuit: a pure-pursuit chase of the rollout from the vehicle's pose at "
        "controller.path_lookahead_m (2.5 m), its curvature clipped at the vehicle's limit "
        "(controller.path_curvature_clip, controller.path_curvature_max_1_per_m): a layer of "
        "ours, not the paper's, the default of the previous release; it makes the baseline's "
        "1-m rollout and improved's 5-m one alike and cut improved's demand more (C2 moved "
        "with the look-ahead: 1.5 m -0.003, 2.5 m -0.075, 4 m -0.35 m/s³ over 100 members)",
        "controller.path_reference, controller.path_lookahead_m, controller.path_curvature_clip, "
        "controller.path_curvature_max_1_per_m"),
    RegisterEntry(
        "Velocity planning V_r = f_v(obstacles)",
        "Section 3.1: 'considers the relative position and motion of obstacles'; 'safety "
        "constraints (e.g., minimum stopping distance)', 'heuristics or optimization "
        "techniques' (off by default; planner.velocity_planning)",
        "predicted_clearance: the fastest of planner.speed_candidates speeds in "
        "[speed_floor_mps, nominal] whose constant-velocity prediction along the APF's path "
        "keeps stop_margin_m of clearance over speed_check_horizon_s (else the speed with the "
        "largest predicted clearance): slowing only where it is predicted to be safer",
        "stopping_distance: the speed that can stop before the nearest obstacle in a corridor "
        "along the heading (the earlier reading; ignores where obstacles go and where the "
        "vehicle steers, and made both methods collide more)",
        "planner.velocity_rule"),
    RegisterEntry(
        "APF path to lateral MPC reference",
        "Section 3.1: y_ref from the rollout; psi_apf = atan2(F_y, F_x), omega_ref = sat(...)",
        "path frame: the rollout as the path (see above); fixed frame: lateral "
        "reference = rollout interpolated at the MPC's predicted stations, heading reference = "
        "path slope, saturated at controller.heading_ref_max_rad",
        "apf_force: heading ramps toward psi_apf at the saturated rate omega_max (in the path "
        "frame the path's heading does)",
        "controller.heading_reference"),
    RegisterEntry(
        "Reference beyond the end of the rollout",
        "the baseline rollout covers only Np * 0.1 m = 1 m, the MPC looks vx * Np * Ts ahead",
        "extend the last rollout segment linearly (slope saturated in the fixed frame)",
        "hold: keep the last lateral position (continue parallel to the start-goal line)",
        "controller.path_beyond_end"),
    RegisterEntry(
        "Inputs after the control horizon",
        "Nc = 3 (Appendix A, MATLAB: manipulated variable held after Nc)",
        "hold_last: steering rate held at its Nc-th value", "zero_rate: steering angle held",
        "controller.input_hold"),
    RegisterEntry(
        "Collision-avoidance constraints 'from APF'",
        "'Collision avoidance constraints from APF' (no formula)",
        "one soft half-plane per obstacle and horizon step, side chosen by the APF reference: "
        "sigma (y_k - o_y) >= sqrt(R^2 - (x_k - o_x)^2), sigma = sign(y_ref,k - o_y), "
        "R = r_o + r_v + margin (exact for the disk at the MPC's station x_k; in the path "
        "frame in path coordinates, the obstacle's predicted centre projected to (s, d))",
        "radial: n . (p_k - o_k) >= R, n from the predicted obstacle toward the APF reference "
        "point (tangent plane; mostly longitudinal, so a lateral MPC can meet it only with slack)",
        "controller.halfplane_normal"),
    RegisterEntry(
        "Who avoids the obstacle: the APF or the MPC's constraints",
        "the APF plans the avoiding reference and the MPC carries 'collision avoidance "
        "constraints from APF' (Section 3); the claims (Tables 1-2) are the APF's",
        "on: the soft half-planes above guard every method, so the family ledger judges each "
        "APF together with constraints all methods share",
        "off: no half-planes on any backend or track, the APF's reference alone keeps the "
        "vehicle off the obstacles (make reproduce's apf_alone families: the 'APF by itself' "
        "ledger beside the default one)",
        "controller.collision_constraints"),
    RegisterEntry(
        "Time alignment of y_ref in nlmpcmove (kinematic track)",
        "y_ref = [p_1; ...; p_Np] with p_1 the current position, passed to nlmpcmove",
        "literal: row i is the reference of predicted step i, as nlmpcmove reads it (so step 1 "
        "tracks the current position)", "shifted: row i + 1 for step i",
        "controller.reference_alignment"),
    RegisterEntry(
        "Discretization of the kinematic prediction model",
        "Appendix A advances x(k+1) = x(k) + f(x, u) Ts; nlmpc's own discretization is not given",
        "forward Euler for the MPC's prediction (as Appendix A's loop); the plant integrates the "
        "same ODE exactly with RK4 substeps", "-", "scenario.plant_substeps"),
    RegisterEntry(
        "C1: whose appearance starts the reaction clock",
        "Table 1: 'how quickly the system reacts to a suddenly appearing obstacle'",
        "the first obstacle that threatens the vehicle's straight continuation when it appears; "
        "the band crossing interpolated between samples", "first_visible (any obstacle, even a "
        "harmless one); sample (first sample outside the band)",
        "metrics.reaction_obstacle, metrics.reaction_interpolation"),
    RegisterEntry(
        "What threatens", "'sudden obstacle', 'collision risk' (no definition)",
        "an obstacle whose constant-velocity motion comes within both radii + 0.5 m of the "
        "straight continuation of the vehicle's motion at any time before the run ends; an "
        "obstacle the vehicle collides with threatened by definition",
        "a fixed look-ahead (threat_horizon_s = 3 s, the older reading: a threat that appears "
        "later than that before contact goes unseen); other margins",
        "metrics.threat_margin_m, metrics.threat_horizon_s"),
    RegisterEntry(
        "C2: lateral acceleration and window", "Table 1: 'smooth curvature and gradual turns'",
        "a_y = vy_dot + vx r; jerk over the avoidance window (threat to recovery)",
        "vx_r (drops vy_dot); whole_run", "metrics.lateral_accel, metrics.smoothness_window"),
    RegisterEntry(
        "C2: whose window", "Table 1: 'sharp turns after avoidance (jerky)' (no window given)",
        "own: each run's RMS jerk over its own avoidance window (the method that recovers "
        "later is measured over a longer, mostly quiet span, which dilutes its RMS)",
        "common: both runs of a pair over one window made of their two, the union (from the "
        "earlier start to the later end: every sample either own window holds, so neither "
        "method's late jerks are cut off; the report shows this row beside the default) or "
        "the intersection (claims.common_window)",
        "claims.c2_window, claims.common_window"),
    RegisterEntry(
        "C3 as Table 2's two halves (C3a, C3b)",
        "Table 2: 'strong repulsion only when needed'; baseline: 'low sensitivity for far "
        "distances'",
        "C3a: the share of repulsive impulse applied while no obstacle threatens the straight "
        "continuation and none is within near_field_m (force holding the vehicle off a near "
        "obstacle is needed); C3b: time to contact at the onset of significant repulsion "
        "during a threat (higher = earlier)",
        "threat: only a threat makes repulsion needed (force while passing close counts as "
        "waste); clearance_band: repulsion beyond threat_clearance_m of clearance is unneeded",
        "metrics.repulsion_need, metrics.near_field_m, metrics.repulsion_onset_force"),
    RegisterEntry(
        "C4: which recovery", "Table 1: 'returns smoothly to goal direction'",
        "settling time of the lateral error into recovery_lateral_band_m after every threat "
        "is passed (the vehicle back on its line)",
        "heading: settling of the heading error to the goal's bearing into "
        "recovery_heading_band_rad ('goal direction' read as heading)",
        "metrics.recovery_reading, metrics.recovery_lateral_band_m"),
    RegisterEntry(
        "C4, C5: when every threat is passed", "Table 1: 'after avoidance' (one sudden "
        "obstacle, passed once)",
        "once the vehicle is ahead of every obstacle that ever threatened by both radii, for "
        "good (ahead_of_threats); among recorded pedestrians last_threat (below), since a "
        "walker who once threatened may walk ahead of the platform for the whole crossing: "
        "the default found a pass in 45 of 163 clean pairs (C5 on 45, C4 on 11), last_threat "
        "C5 on 135 and C4 on 17 (improved settles after the last threat in 29 of 200)",
        "last_threat: from the first step after which no obstacle threatens the straight "
        "continuation any more (make pedestrians' experiments; the obstacle collided with "
        "threatens until the run's end)",
        "metrics.pass_reading"),
    RegisterEntry(
        "C5: what counts as oscillation", "Table 1: 'no sharp drops or oscillations'",
        "reversals of the lateral error after the obstacle is passed, net of the manoeuvre",
        "sign_changes_whole_run (lateral error + yaw rate over the run, the out-and-back "
        "included)", "metrics.oscillation"),
    RegisterEntry(
        "Safety check between samples", "(not in the paper)",
        "continuous: closest approach of linearly interpolated vehicle and obstacles between "
        "log rows; collisions attributed by a sampled reachability check (constant and "
        "two-phase steering and speed profiles within the track's actuators), published as "
        "unavoidable only where no method that ran the same scenario avoided it",
        "sampled: clearance at the log rows only; constant steering targets only "
        "(attribution_switch_samples=0)",
        "metrics.collision_check, metrics.attribution_steering_samples, "
        "metrics.attribution_switch_samples"),
    RegisterEntry(
        "From paired differences to an outcome", "Tables 1-2 are qualitative",
        "Hodges-Lehmann estimate with its interval at 1 - alpha/7 (Bonferroni over the seven "
        "claims); the interval is the test: a direction exactly when it excludes 0; the "
        "Wilcoxon signed-rank test shown beside it; C1-C5 on pairs where neither collided, "
        "margins per claim (Methods section)",
        "median / intervals at 1 - alpha (none) / sign test / all pairs / unsettled_last (C1 "
        "and C4 also on the pairs where a run's clock started and its event never came before "
        "the run ended, that run ranked last: make pedestrians' rule, since among walkers "
        "improved rarely settles after the last threat and the default leaves C4 on 17 of 200 "
        "crossings; its ledgers show the default beside) / other margins",
        "claims.estimator, claims.interval_adjustment, claims.test, claims.pairs, "
        "claims.catalogue"),
    RegisterEntry(
        "When a tuned method's search has converged", "(not in the paper: it tunes nothing)",
        "its feasible front's hypervolume (fixed bounds shared by both methods) grew by at most "
        "2 % over the last 60 trials, at 80 trials at the earliest and 300 at the latest; 10 "
        "replicates, each judged on its own held-out family; a claim is settled when a "
        "one-sided exact binomial test of its leading outcome's count among the judged "
        "replicates is significant at claims.alpha (9 of 10 at 0.05); objectives censor a "
        "member that never recovers at the run's end",
        "other tolerance, window, bounds or replicates; another alpha; censoring: drop",
        "tune.convergence_tolerance, tune.convergence_window, tune.hypervolume_bounds, "
        "tune.replicates, tune.settled_test, tune.censoring"),
    RegisterEntry(
        "Comparable encounters (kinematic track)",
        "Appendix A's baseline reference crawls at 1 m/s",
        "a claim is compared on the kinematic track only when both methods come within 2 m of "
        "the obstacle", "any other distance", "claims.comparable_clearance_m"),
    RegisterEntry(
        "Run length", "100 steps of 0.1 s (Appendix A)",
        "130 steps: at 3 m/s a 100-step run ends at the goal line before the vehicle can settle; "
        "the run stops early once the goal line is reached",
        "100 (literal)", "scenario.n_steps"),
    RegisterEntry(
        "Which figure shows which method", "Table 2 labels its columns 'First Graph "
        "(Improved)' and 'Second Graph (Original)', while the text says Figure 2 is the existing "
        "method and Figure 3 the improved one",
        "the text: Figure 2 = baseline (ref. [18]), Figure 3 = improved; Table 2's column labels "
        "are read as swapped", "the column labels (Figure 2 = improved)", "(none: naming only)"),
    RegisterEntry(
        "The Appendix-A controller", "MATLAB nlmpc (fmincon on the nonlinear kinematic model)",
        "an LTV-QP linearized about the previous plan once per step (fast; its agreement with "
        "the nonlinear program is measured by make nmpc-check)",
        "nmpc: the nonlinear program itself (CasADi + IPOPT, single shooting on the Euler "
        "model)", "controller.backend"),
    RegisterEntry(
        "The baseline's reference on the Appendix-A track",
        "p(k+1) = p(k) + alpha F_total (Section 2, printed without normalization) while ref. "
        "[18] normalizes; nlmpcmove receives the APF's positions row by row",
        "the formula as printed (planner=baseline_printed: normalize_step = false), chosen by "
        "the rule: among the readings under which both methods meet the obstacle (within "
        "claims.comparable_clearance_m), the one whose runs match most of the paper's words "
        "about its figures (features.*; 5 of 9 here). It meets the obstacle at 0.17 m with "
        "+-0.4 rad chattering steering (jerk RMS 45 m/s³)",
        "literal (ref. [18]'s normalized 0.1 m steps, row k for step k: the baseline crawls at "
        "about 0.83 m/s and never comes within 4.49 m of the obstacle; 3 of 9); path-indexed at "
        "the planned speed (controller.reference_alignment=path_speed, Section 3.1: 0.06 m; 4 "
        "of 9); shifted rows (2.99 m); the obstacle placed relative to the vehicle when it "
        "appears (scenario.obstacle_anchor=vehicle, Figure 1's 'after the mobile platform moved "
        "in three seconds', literal baseline otherwise: 0.20 m); a normalized 0.3 m step "
        "(collides). The track's family ledger uses the default; the paper scenario's outcomes "
        "under each reading sit beside it as a sensitivity",
        "planner.normalize_step, planner.step_size, controller.reference_alignment, "
        "scenario.obstacle_anchor"),
    RegisterEntry(
        "The platform among recorded pedestrians (a choice we add; the paper has no "
        "pedestrians)", "a vehicle on a road with one sudden obstacle",
        "a sidewalk robot (vehicle=sidewalk_robot: a 0.35 m disc) on the Appendix-A kinematic "
        "track, which brakes to a stop, its reference spaced by its speed along the APF's path "
        "(controller.reference_alignment=path_speed; literally, improved's 0.5 m step cap drove "
        "it at 3.6-7 m/s), 50 obstacle slots, the run ended at its first contact",
        "the compact car on the lateral track with 3 slots and crossings aimed at a walker "
        "(experiment=pedestrians_car, a row of make pedestrians: 77 % / 90 % collisions; at its "
        "30 crossings every claim inconclusive, C1-C5 on 1-2 clean pairs); the robot "
        "on the lateral track braking to a stop (experiment=pedestrians_lateral: the hand-over "
        "to the kinematic single-track below 0.6 m/s, velocity planning to a floor of 0; 30 "
        "crossings: 17 % / 37 % collisions)",
        "vehicle, controller, controller.reference_alignment, controller.max_obstacles, "
        "scenario.pedestrians.end_at_contact"),
    RegisterEntry(
        "The sidewalk robot's speed limits (a choice we add)",
        "Appendix A's nlmpc bounds the acceleration and the steering angle, not the speed",
        "among recorded pedestrians the kinematic MPC's predicted speed stays within the "
        "robot's published top speed, 1.67 m/s, forward and in reverse (a skid-steered robot "
        "backs up as it drives; the rows widen to hold a measured speed outside them); "
        "without them the baseline's plans reached 6 m/s and improved's reversed at up to "
        "2.4 m/s (collisions 7 % / 13.5 %, improved / baseline, 200 crossings; with the "
        "limits 8.5 % / 14 %, C2 contradicted where it was inconclusive). The paper's "
        "kinematic track: null, no speed rows",
        "[0, 1.67], no reversing: collisions 22 % / 29 %, 35 of improved's 44 contacts with "
        "the robot standing (the recorded walkers do not react to it), C1 and C5 "
        "inconclusive (69 and 100 clean pairs) where the default finds C1 supported and C5 "
        "contradicted",
        "controller.speed_bounds_mps"),
    RegisterEntry(
        "How a crossing among pedestrians is drawn (a choice we add)", "-",
        "between places someone walked at any time of the recording (scenario.pedestrians."
        "draw=scene: the midpoint a recorded position, start and goal within "
        "walkable_radius_m = 1 m of one); the straight line meets a walker on 66 % of crossings",
        "aimed: the midpoint where a walker will be when the platform arrives (the straight line "
        "meets a walker on every crossing; experiment=pedestrians_aimed, 30 crossings: "
        "collisions 0 % / 23 %; C3a and C3b as in the default family, C0, C1, C2, C4 and C5 "
        "inconclusive)",
        "scenario.pedestrians.draw, scenario.pedestrians.walkable_radius_m"),
    RegisterEntry(
        "Walkers' behaviour (a choice we add)", "-",
        "replayed on their recorded tracks (they never react)",
        "reactive: Helbing and Molnar's social force towards each walker's recorded position "
        "social_lookahead_s ahead, avoiding the others and the platform "
        "(experiment=pedestrians_reactive, 30 crossings: collisions 0 % / 20 %; C3a, C3b and "
        "C4 as in the default family, C0, C1, C2 and C5 inconclusive)",
        "scenario.pedestrians.walkers, scenario.pedestrians.social_*"),
    RegisterEntry(
        "Walkers before their first and after their last recorded sample (a choice we add)",
        "-",
        "each recorded track goes on scenario.pedestrians.track_extension_s = 1 s beyond both "
        "ends at its end segment's velocity (a track begins where the camera's annotated area "
        "does, not where the walker did; 1 s: the sidewalk robot's time to stop from its top "
        "speed). 200 crossings: collisions 3.5 % / 11.5 % (improved / baseline), 0 of "
        "improved's on the 115 crossings where standing still is safe; C0 supported",
        "0: the recording as it is, walkers appear and vanish at the area's edge, some on the "
        "robot: collisions 8.5 % / 13.5 %, 6 of improved's 17 contacts on the very step the "
        "walker appeared; C0 inconclusive (-0.05 [-0.13, 0.03]), the other outcomes the same",
        "scenario.pedestrians.track_extension_s"),
    RegisterEntry(
        "Clarabel's iterative refinement (a solver setting we choose)",
        "MATLAB's mpc/nlmpc solvers, their settings not given",
        "on (Clarabel's default) for every QP except make pedestrians' kinematic families: off "
        "there, about a third cheaper per QP and as accurate at the optimum (3,223 of their "
        "QPs against a solve at 1e-10: 99th percentile of the input difference 2.1e-6 off, "
        "3.9e-6 on); the same outcomes on the 200 crossings, every estimate within 0.003",
        "off on the Appendix-A track: the same accuracy, but its baseline's chaotic runs carry "
        "the other last digits on (8 of 50 collision verdicts flip, C3b against the baseline "
        "turns supported); not taken there",
        "controller.solver_refinement"),
    RegisterEntry(
        "Shapes on CommonRoad's roads (a choice we add; the paper's obstacles are discs)",
        "a vehicle and round obstacles",
        "every rectangle covered by scenario.commonroad.cover_discs = 3 equal discs along its "
        "long side (each obstacle disc its own half-plane, 24 slots filled nearest first); the "
        "ego likewise (vehicle.footprint_discs: the lateral MPC keeps out the ego disc nearest "
        "to each obstacle along the path, the kinematic track the one nearest at each predicted "
        "pose, the checks measure from every disc; the peers see the ego as one disc of the "
        "cover's radius). Our check is the "
        "stricter: the discs bulge up to 0.27 m beyond a car's sides",
        "circumscribed: one disc holding each shape and the ego one vehicle.footprint_radius_m "
        "disc (earlier releases: a car 2.4 m round, a car in the next lane 'collided'); "
        "half_width (under-covers)",
        "scenario.commonroad.obstacle_disc, scenario.commonroad.cover_discs, "
        "vehicle.footprint_discs, vehicle.footprint_span_m"),
    RegisterEntry(
        "Braking to a stop on the lateral track (a choice we add; the paper's speed never "
        "falls below the model's)", "the lateral model has 1/v_x terms",
        "off (vehicle.kinematic_below_mps = null): the speed floor stays at "
        "vehicle.min_model_speed_mps and the plant keeps its tyre law at every speed",
        "a hand-over speed: below it the plant and the MPC's model are the kinematic "
        "single-track (no slip, no 1/v_x term), so planner.speed_floor_mps may be 0 (a car that "
        "cannot pass a wall stops 1 m short of it instead of driving through)",
        "vehicle.kinematic_below_mps"),
    RegisterEntry(
        "What the ego sees on a CommonRoad road (a choice we add; the paper's obstacle "
        "appears at a scripted time)", "an obstacle that appears suddenly",
        "obstacles within scenario.commonroad.sensor_range_m = 60 m (centre distance) whose "
        "line of sight from the ego crosses no static obstacle's rectangle (a parked car hides "
        "what stands behind it); anything within the ego's reach is seen. The sight line "
        "starts at the ego's logged position (its centre, not its front or a sensor's mount; "
        "the same for the Euro NCAP tests' parked cars)",
        "occlusion=false, sensor_range_m=null: every present obstacle seen from its first "
        "recorded step (earlier releases: nothing appeared)",
        "scenario.commonroad.sensor_range_m, scenario.commonroad.occlusion"),
    RegisterEntry(
        "Where the attraction pulls on a CommonRoad road (a choice we add; the paper's road "
        "is straight)", "the goal attracts",
        "along the road: at every point of the APF's rollout the attraction pulls towards the "
        "point ahead on the route's lanelet centreline (the shortest lanelet path to the "
        "goal's lanelet) by the farther of route_lookahead_m = 10 m and route_lookahead_s = "
        "2 s at the ego's speed (a pure pursuit's look-ahead time), so the rollout the MPC "
        "follows keeps to the road through a bend",
        "straight towards the goal point (route_lookahead_m = null; earlier releases: ZAM_"
        "Tjunction 50 steps off the road cutting its junction's corner); a fixed distance "
        "(route_lookahead_s = null: 10 m sends US101-23_1 at 17 m/s into a skid, 115 steps "
        "off the road; 30 m misses the junction's turn); 10 m and 1.5 s (US101-23_1 24/41 "
        "steps off the road); the point ahead of the ego alone held for the whole rollout "
        "(earlier releases' reading: the rollout stops at it). On the eight public files "
        "(docs/commonroad.md) one method at least keeps to the road in 6 of 8 files over the "
        "run, as straight to the goal (7 of 8 up to the first contact under both); the "
        "file's goal is reached in 6 runs of 16 (7 straight to the goal, two of them across "
        "the junction's corner), contact in 7 (6)",
        "scenario.commonroad.route_lookahead_m, scenario.commonroad.route_lookahead_s"),
    RegisterEntry(
        "What a CommonRoad road is where its lanelets do not meet exactly (a choice we add)",
        "-",
        "the file's lanelets, each widened by lanelet_gap_m / 2 = 3 cm to every side (a "
        "mitred buffer), so that neighbours whose shared edges leave a hairline gap are one "
        "road, for the MPC's road rows and for the off-road count alike: USA_US101-23_1's "
        "lanelets leave gaps of up to 3 cm (37 holes in their union), which held the ego in "
        "its lane (the MPC's road reach ended at the gap) and counted a car over a lane "
        "marking as off the road",
        "the lanelets as they are (lanelet_gap_m = 0; earlier releases): on the eight public "
        "files (docs/commonroad.md) US101-23_1 then has 4 / 2 steps off the road before "
        "contact (improved / baseline, every one over a gap between lanelets) and improved "
        "touches a car; with the widened road 0 / 0, no contact, and the baseline reaches the "
        "file's goal; US101-3_1, where a faster car cuts in from behind, becomes a contact "
        "for both (one step on the true shapes; 1.2-1.4 m clear when held in the lane), "
        "US101-3_3's baseline no contact: 7 contacts of 16 runs either way, 7 goals against 6",
        "scenario.commonroad.lanelet_gap_m"),
    RegisterEntry(
        "Steps off a CommonRoad road that count (a choice we add)", "-",
        "those before the first contact on the true shapes (off_road_steps_before_contact: "
        "nothing after a crash is judged, the field's convention, as the Euro NCAP outcome "
        "reads its runs up to their first true overlap); the whole run's count "
        "(off_road_steps) beside it in the report",
        "the whole run's count alone (earlier releases; Guetersloh's methods leave the road "
        "only after their contact at 1.5 s)",
        "(none: both counts are reported)"),
    RegisterEntry(
        "Success on a CommonRoad file (a choice we add)", "-",
        "the file's own criterion: its goal region reached (position, time step, orientation "
        "and speed intervals; CommonRoad's goal_reached) without contact on the true shapes; "
        "the run still ends at our goal line or the goal's last time step, and where the two "
        "goals differ the report says why",
        "our goal line (the paper's scenario: the run ends on crossing it)",
        "scenario.commonroad.n_steps"),
    RegisterEntry(
        "The road's edges in the MPC (a choice we add; the paper's road has no edges)", "-",
        "on a road (CommonRoad's lanelets, a Euro NCAP test's two lanes) the lateral MPC's path "
        "frame gets two more soft half-planes per step keeping the ego's disc plus the safety "
        "margin inside the road along the path's normal, their rows weighted as a collision "
        "row (controller.road_edge_weight = 1; the paper's scenario: null, none). Only the "
        "lateral MPC in the path frame takes them: the peers' controllers and the kinematic "
        "MPC see no road. On the public CommonRoad files: steps off the road 17 -> 4-5 "
        "(Guetersloh), 6 -> 0 (US101-23_1, whose improved then touches a car), 133 -> 50 "
        "(ZAM_Tjunction, both then reach its goal)",
        "null: no road in the MPC (earlier releases)", "controller.road_edge_weight"),
    RegisterEntry(
        "The steering bound at road speeds (a choice we add; the paper's car drives at 3 m/s)",
        "delta in [-0.4, 0.4] (Appendix A)",
        "on a road (CommonRoad files, the Euro NCAP tests) the lateral MPC of improved and the "
        "baseline bounds each step's steering by the tyres' friction at the step's model speed: "
        "the smaller of vehicle.steering_max_rad and atan(s mu g L / v^2), the angle at which a "
        "kinematic single-track's lateral acceleration reaches s = 1 times mu g "
        "(controller.steering_friction_share = 1.0; 0.15 rad at 12 m/s, 0.055 at 20; no effect "
        "below about 7 m/s, so none on the paper's scenarios, which keep null). Without it the "
        "linear MPC plans up to 0.4 rad at 12-20 m/s, far past the tyres' saturation: a car "
        "parked in the lane 30 m ahead at 12 m/s ends in a skid off the road (135 steps; with "
        "the bound 5, the car passed touching it); on the Euro NCAP tests steering alone "
        "avoids 45 / 41 of 110 without it (improved / baseline; off the road in 38 / 6) and "
        "35 / 36 with it (21 / 3): the tests lost are last-moment swerves at 35-55 km/h that "
        "passed 2-24 cm from the walker. The peers' controllers and the nonlinear MPC (whose "
        "tyres saturate in its model) do not take it",
        "null: vehicle.steering_max_rad at every speed (earlier releases); any share in "
        "[0.05, 1]", "controller.steering_friction_share"),
    RegisterEntry(
        "How hard the car can brake (a choice we add; Appendix A bounds a in [-3, 3] m/s^2)",
        "a in [-3, 3] m/s^2 (the kinematic nlmpc's input bound)",
        "the plant's speed loop accelerates at up to vehicle.accel_max_mps2 = 3 m/s^2 and "
        "brakes at up to vehicle.brake_max_mps2: null (3, the paper's scenarios), 8 m/s^2 where "
        "the lateral track brakes on a road (the Euro NCAP braking track, with Section 3.1's "
        "velocity planning from every obstacle's prediction planned at "
        "planner.braking_decel_mps2 = 6: a passenger car's full braking on dry asphalt, "
        "below the tyres' mu g = 8.8). There both methods avoid 110 of 110 tests; braking at "
        "3 m/s^2 (planned at 6) a car parked 33 m ahead at 20 m/s is hit (67 m are needed to "
        "stop), at 8 it is stopped short of by 4.7 m. The braking track's earlier reading "
        "(the stopping distance in a corridor ahead, planned and braked at 3) avoided 67 / 86 "
        "(improved / baseline), none of CPNA-25; the prediction rule planned at 3 avoids "
        "101-102 / 102 whether the car brakes at 3 or 8",
        "null: vehicle.accel_max_mps2 both ways (earlier releases); any value in [0.001, 50]",
        "vehicle.brake_max_mps2"),
    RegisterEntry(
        "Braking on a CommonRoad road (a choice we add; the paper's car holds its speed)",
        "a constant speed (Section 3.1's velocity planning is not used in the paper's runs)",
        "apf-mpc commonroad gives the methods of the lateral MPC the Euro NCAP braking track's "
        "keys (each unless the command line sets it; none with planner.velocity_planning "
        "given): Section 3.1's velocity planning as "
        "the register reads it (planner.velocity_rule = predicted_clearance, every "
        "obstacle's prediction, behind included), down to a stop (planner.speed_floor_mps = "
        "0), planned at planner.braking_decel_mps2 = 6 by a car that brakes at "
        "vehicle.brake_max_mps2 = 8, the kinematic single-track below "
        "vehicle.kinematic_below_mps = 2. On the eight public files 11 of 16 runs reach the "
        "file's goal and 5 touch (at a constant speed 7 and 7; improved is then hit at "
        "ZAM_Tjunction, where it was not); the planted parked cars 30-33 m ahead at 12-20 m/s "
        "are stopped short of by 4.7-5.1 m (at a constant speed both methods hit them)",
        "planner.velocity_planning=false: the paper's constant speed; "
        "planner.velocity_rule=stopping_distance: the earlier rule, the other braking keys "
        "kept",
        "planner.velocity_planning, planner.velocity_rule"),
    RegisterEntry(
        "The Euro NCAP tests (a choice we add; the paper's sudden obstacle is what they test)",
        "an obstacle that appears suddenly in front of a car",
        "our reading of Euro NCAP's AEB/LSS VRU protocol (to be checked against it): five "
        "cases, CPNC-50 (a child from between two parked cars, near side), CPFA-50 (an adult "
        "from the far side), CPNA-25/-75 (an adult from the near side) and CBNAO-50 (a cyclist "
        "from behind a parked car); test speeds 10-60 km/h in 5 km/h steps, each test driven "
        "within 1 km/h of its grid speed; impact positions as fractions of the ego's 1.8 m "
        "width from the side the road user comes from",
        "any subset of the cases, other speed grids and tolerances",
        "scenario.source.params.cases, scenario.source.params.ego_speeds_kmh, "
        "scenario.source.params.speed_tolerance_kmh"),
    RegisterEntry(
        "The Euro NCAP road users and obstructions (a choice we add)", "-",
        "child 5 km/h (a 0.25 m disc), adults 5 km/h near side and 8 km/h far side (0.3 m), "
        "cyclist 15 km/h (a 1.9 x 0.6 m bicycle covered by discs); starting 4 m (near) or "
        "6 m (far) from the ego's centreline, standing still until the ego has driven "
        "lead_time_s = 1 s, then at constant speed (the protocol's acceleration left out); "
        "parked cars 4.5 x 1.8 m, 1 m outside the ego's side, hiding what is behind them",
        "other speeds, sizes, starts and gaps; occlusion=false",
        "scenario.source.params.child_speed_kmh, scenario.source.params.adult_far_speed_kmh, "
        "scenario.source.params.cyclist_speed_kmh, scenario.source.params.near_start_m, "
        "scenario.source.params.lead_time_s, scenario.source.params.parked_lateral_gap_m, "
        "scenario.source.params.occlusion"),
    RegisterEntry(
        "The Euro NCAP outcome and the road (a choice we add)", "-",
        "the protocol's, on the true shapes (the car's 4.5 x 1.8 m rectangle, the road user's "
        "disc or the bicycle's rectangle, the parked cars' rectangles): the road user hit or "
        "not, and the ego's speed at the first overlap; contact with a parked car and the "
        "steps the rectangle spends beyond the road's edges (its lane and an oncoming lane, "
        "3.5 m each) reported beside it. The run goes on after it (end_at_contact=false): its "
        "own check sees the disc covers, which reach 0.27 m beyond the car's sides",
        "oncoming_lane=false (one lane); end_at_contact=true (the run ends at the covers' "
        "first contact)",
        "scenario.source.params.lane_width_m, scenario.source.params.oncoming_lane, "
        "scenario.source.params.end_at_contact"),
    RegisterEntry(
        "Which methods run the Euro NCAP tests (a choice we add)", "-",
        "on both tracks improved, the baseline, MPC-DCBF and the CBF filter; velocity "
        "obstacles and the dynamic window are left out: their candidate speed and speed limit "
        "are set for the paper's 3 m/s and the tests drive 10-60 km/h. A third track, "
        "lateral_braking, runs the paper's two methods braking (velocity planning by the "
        "stopping distance to a stop at the vehicle's 3 m/s^2, the kinematic hand-over below "
        "2 m/s): the protocol's tests are built for braking, the paper's MPC steers at a "
        "constant speed",
        "-", "(none: the methods and tracks make euro-ncap runs)"),
)


#: The opening of ``docs/register.md`` (:func:`register_markdown`).
REGISTER_PAGE_OPENING = (
    "# The interpretation register\n\n"
    "Back to the [README](../README.md).\n\n"
    "Every place where the paper is ambiguous, the reading this reproduction chose, the "
    "alternatives, and the config key that flips it. The report's own register (the section "
    "\"Interpretation register\" of its appendix page, `appendix.html`) lists the same entries "
    "with the value each run used; this page is written from `pipeline/register.py`, the one "
    "source of both (`python -m pipeline.register > docs/register.md`).\n\n"
    "| topic | the paper says | our default reading | alternatives | config key |\n"
    "|---|---|---|---|---|\n")


def register_markdown(entries: tuple[RegisterEntry, ...] = INTERPRETATION_REGISTER) -> str:
    """``docs/register.md``: :data:`REGISTER_PAGE_OPENING` and one table row per entry (a
    ``|`` inside a cell escaped)."""

    def cell(text: str) -> str:
        return text.replace("|", "\\|")

    rows = [f"| {cell(e.topic)} | {cell(e.paper_says)} | {cell(e.default)} | "
            f"{cell(e.alternatives)} | `{e.config_key}` |\n" for e in entries]
    return REGISTER_PAGE_OPENING + "".join(rows)


if __name__ == "__main__":
    import sys

    sys.stdout.write(register_markdown())
