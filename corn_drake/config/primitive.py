"""The contact-primitive policy's configs: how one primitive is executed (PrimitiveConfig, the
executor's and the primitive env's), and what a primitive training run records
(PrimitiveTrainConfig, `corn-drake train --policy primitive`, RUN/config.yaml).

A primitive: a contact location on the object's cloud (a point with its outward surface normal)
and a push motion. The executor (systems/primitive_executor.py) moves the tool up to `clearance`
above the object's top, across to above the pre-contact point (`pre_contact_distance` off the
surface along the normal), down to it, pushes by the motion over `push_steps` policy periods and
lifts `retreat_height`. Distances are metres; step counts are policy periods (0.1 s).

No `from __future__ import annotations`: yaml_load_typed needs real types on the fields.
"""

import dataclasses as dc

from corn_drake.config.bounds import check_bounds
from corn_drake.config.choices import (PRIMITIVE_CHOOSERS, PRIMITIVE_LOCATIONS,
                                       PRIMITIVE_REWARD_POINTS)
from corn_drake.config.teacher import TeacherDiagramConfig
from corn_drake.config.training import RunSettings
from corn_drake.errors import InputError

# At rest: the object slower than this (m/s, rad/s). success_at_rest's default, and what
# evaluate's reports count as a success that ended still (evaluation/failures.py).
REST_LINEAR_SPEED = 0.02
REST_ANGULAR_SPEED = 0.2


def at_rest(speed: dict, linear: float = REST_LINEAR_SPEED,
            angular: float = REST_ANGULAR_SPEED) -> bool:
    """Whether an object speed {"linear" (m/s), "angular" (rad/s)} is under the rest speeds:
    the one rule the env's success_at_rest (with its config's speeds) and the reports'
    successes_ending_still (with the defaults) share."""
    return speed["linear"] < linear and speed["angular"] < angular


@dc.dataclass
class PrimitiveConfig:
    # Range checks (config/bounds.py): what check_bounds refuses.
    BOUNDS = {"pre_contact_distance": "> 0", "clearance": "> 0", "min_tool_height": ">= 0",
              "push_distance": "> 0", "push_steps": ">= 1", "retreat_height": ">= 0",
              "retreat_steps": ">= 1", "reach_tolerance": "> 0", "turn_tolerance": "> 0",
              "approach_steps": ">= 1",
              "max_primitives": ">= 1", "stiffness": "[-1, 1]", "damping": "[-1, 1]",
              "progress_reward": ">= 0", "tip_penalty": ">= 0", "push_height": ">= 0",
              "vertical_push": "[0, 1]", "finger_tilt_deg": "[0, 60]",
              "turn_reward": ">= 0", "exit_penalty": ">= 0", "table_margin": ">= 0",
              "rest_linear_speed": "> 0", "rest_angular_speed": "> 0",
              "settle_steps": ">= 0", "settle_motion": "> 0", "tilt_stop_deg": "[0, 90]"}
    # The tool point stops this far off the surface along the normal before the push. The
    # closed fingers are 0.021 x 0.04 m around the tool point, so 0.04 leaves ~2 cm of air.
    pre_contact_distance: float = 0.04
    # The tool travels this far above the object's highest bounding-box corner, so the fingers
    # (their tips 9 mm below the tool point) pass over the object, never through it.
    clearance: float = 0.05
    # The tool point never aims lower than this above the table top (the fingertips are 9 mm
    # below it): a contact point near the table is pushed from just above the table.
    min_tool_height: float = 0.015
    # The push motion at |a| = 1 per axis (m): the policy's motion in [-1, 1]^3 times this.
    # The push starts pre_contact_distance (4 cm) off the surface, so 0.1 moved an object at
    # most ~6 cm along an axis, less than the push task's 8-12 cm goals: random primitives
    # then succeeded in 0.10 of push episodes, with 0.15 in 0.18-0.21 (first 1,000 primitives).
    push_distance: float = 0.15
    # Policy periods the push lasts: the tool's target moves from the pre-contact point to the
    # push's end in this many equal steps (each within the controller's max_position_delta).
    push_steps: int = 4
    retreat_height: float = 0.05
    retreat_steps: int = 2
    # The pre-contact pose counts as reached when the tool point is within this of it.
    reach_tolerance: float = 0.015
    # The descent starts once the hand's turn (fingers down, narrow side to the surface) is
    # within this many radians of its target.
    turn_tolerance: float = 0.15
    # Policy periods the approach (up, across, down) may take before the primitive is given up
    # as unreached (an obstacle, an unreachable point): then the tool only retreats.
    approach_steps: int = 20
    # After the retreat the hand waits, holding still, until no box keypoint of the object has
    # moved more than settle_motion (m) over the last policy period (2 mm per 0.1 s: the rest
    # speed 0.02 m/s), for at most this many periods; then the next primitive may start. Why:
    # the retreat lasts 0.2 s, and in 21 % of the states a primitive was chosen from, the
    # object was still rolling or sliding (every candidate there moved it > 5 mm): the
    # pre-contact point, taken from the cloud at the choice, was stale by the time the hand
    # came down, and the outcome of what was chosen depended on motion no policy input shows
    # (docs/results/primitive/, item 37). 0: no waiting (shipped cards replay as they were).
    settle_steps: int = 0
    settle_motion: float = 0.002
    # The push stops, and the hand retreats, as soon as the object's up direction has turned
    # more than this many degrees since the push began (from its box keypoints, every policy
    # period). Why: on push_turn a tipped or rolled object is a failed episode, and a tip can
    # be seen starting where it cannot be predicted. Measured with the outcome chooser on the
    # 200 unseen push_turn episodes: 10 / 5 degrees gave 0.355 / 0.365 against 0.355, as many
    # episodes tipped or rolled (77 / 76 against 72): most of those are lying bottles rolled
    # by a push, which keep rolling after it stops (docs/results/primitive/, item 38). Hence
    # 0 by default: pushes run their length.
    tilt_stop_deg: float = 0.0
    # An episode ends after this many primitives (HACMan's 10), or at the task's episode_steps.
    max_primitives: int = 10
    # The executor's joint stiffness and damping ratio, normalised like the dense action's kp and
    # rho ([-1, 1] over controller.kp_range / rho_range): stiff enough to track 6 cm per step.
    stiffness: float = 0.5
    damping: float = 0.0
    # Reward of one primitive: this times how much it closed the mean distance (m) between the
    # object's bounding-box keypoints and the goal's (the paper's keypoints, whose potential is
    # nearly linear in that distance at these ranges), plus the task's success_reward on
    # success. 10 per metre makes a 5 cm step toward the goal worth 0.5, half a success; the
    # paper's own scale (k1 0.302 x 1.2 per metre, 0.02 for 5 cm) is drowned by the success
    # bonus over a 10-primitive episode.
    progress_reward: float = 10.0
    # Which body points that distance is measured on: "keypoints", the object's 8 bounding-box
    # corners (the paper's); "cloud", the points of the object's surface cloud (the
    # observation's, 512), i.e. the mean length of HACMan's per-point goal flow. Both drop the
    # height of the object's origin (systems/reward.keypoints_at). Measured on push_turn with
    # hindsight goals: "cloud" 0.225 against 0.245-0.295 with the corners (docs/results/
    # primitive/, item 20), hence the corners by default.
    reward_points: str = "keypoints"
    # Plus this times how much the primitive closed the object's rotation to its goal (rad).
    # Why: the keypoint progress is mostly translation (a 0.6 rad turn moves a 10 cm object's
    # box corners ~3 cm, a push goal 8-12 cm), and a critic fitted to it on push_turn chose
    # the locations that translate (docs/results/primitive/, item 11). 0: keypoints only.
    # Measured with 2.0 on push_turn from the push policy: it learned not to touch the object
    # (greedy success 0.010 against 0.185; item 12), hence off by default.
    turn_reward: float = 0.0
    # On tasks whose goal keeps the object's face (push, push_turn; tasks/faces.py), a
    # primitive that leaves the object on another face (tipped or rolled) ends the training
    # episode with this negative reward; 0 turns the rule off. Why: the keypoint progress alone
    # can reward tipping (a box flipped about a horizontal axis can bring its keypoints nearer
    # a turned goal), and push_turn's failures were mostly tipped objects
    # (docs/results/primitive/). Training only: evaluation runs the task's own episode.
    # Measured with 1.0 on push_turn: the policy learned to stop touching the object (greedy
    # success 0.025 against 0.165 without it), hence off by default.
    tip_penalty: float = 0.0
    # A primitive after which the object has left the workspace (off the 0.4 x 0.5 m table:
    # the goal region ends 4-5 cm from its edges) earns this much less. Why: the keypoint
    # progress drops the object's height, so a fall costs only its xy drift, and 29-54 of 200
    # unseen push_turn episodes of the hindsight policies ended off the table. The hindsight
    # copies of that primitive lose it too. Measured with 1.0 (and hindsight_exit_goals off):
    # 39 episodes off the table instead of 45, but 11 never touched and success 0.220 against
    # 0.260 (item 22): the policy pushed less. Hence 0, off, by default.
    exit_penalty: float = 0.0
    # Keep the pushed object on the table: the executor shortens a push along its own direction
    # so that the object, carried as far as the push goes beyond its first
    # pre_contact_distance (air before contact), keeps its centre (of its bounding box)
    # table_margin inside the table's edges (systems/edge_push.py). Why: the exit penalty
    # above taught the policy to push less; this leaves the choice of push to the policy and
    # takes away only the part that throws the object off. Off by default (shipped cards
    # replay their pushes).
    keep_on_table: bool = False
    table_margin: float = 0.03
    # Side pushes aim this high above the table (m; the tool point), lowered from the chosen
    # contact point as far as the object's cloud leaves room for the fingers
    # (systems/low_push.py: a push at mid-height tips an upright bottle or a tall box, one near
    # the table slides it). 0: push at the chosen point's own height.
    push_height: float = 0.0
    # The push's vertical part: the motion's z times push_distance times this. 1: a full 3-D
    # push. Why less: the push policy learned to press down hard (motion z near -1 in most of
    # its pushes), which the push task, blind to orientation, never punished, and which rolls
    # or flips lying cylinders and wedges (29 % of its primitives tipped the object on
    # push_turn's unseen episodes; docs/results/primitive/). With the outcome chooser (which
    # tells its model the push as executed) 0 / 0.5 gave 0.335 / 0.330 against 0.355 on
    # push_turn, as many lying bottles rolled (item 38).
    vertical_push: float = 1.0
    # For a side contact the fingers lean this far (degrees) from vertical toward the surface,
    # the palm away from it (systems/primitive_executor.facing_rotation: with vertical fingers
    # the palm, 2.1 cm deeper than they are, meets a tall object first, 4.5-10 cm above the
    # tool point, and the push tips it). Only where the object's top reaches the palm's lower
    # edge at the pre-contact point (flat objects keep vertical fingers). 0: vertical fingers.
    finger_tilt_deg: float = 0.0
    # Success only at rest: the task's success counts when a primitive has ended (the executor
    # idle again, the hand lifted off) with the object within the task's tolerances and still
    # (under rest_linear_speed m/s and rest_angular_speed rad/s), not at the period the object
    # passes through the goal pose mid-push. Why: the paper's rule (checked every policy
    # period, no stillness check) counts a pose the object flies through: 15 of the shipped
    # push_turn policy's 16 successes on 46 unseen episodes ended mid-push, the object turning
    # at up to 6.4 rad/s (docs/results/primitive/, item 33). Off by default: the task's own
    # rule, the one every report here uses. With hindsight_goals a relabelled success needs the
    # object still too (the observation's object_speed, rl/primitive/hindsight.py).
    success_at_rest: bool = False
    rest_linear_speed: float = REST_LINEAR_SPEED
    rest_angular_speed: float = REST_ANGULAR_SPEED


def check_reward_points(primitive: PrimitiveConfig) -> None:
    """InputError unless `primitive.reward_points` is one the env knows (the run's config and a
    PrimitiveEnv built from a PrimitiveConfig alone both ask)."""
    if primitive.reward_points not in PRIMITIVE_REWARD_POINTS:
        raise InputError(f"primitive.reward_points must be one of "
                         f"{', '.join(PRIMITIVE_REWARD_POINTS)}, got "
                         f"{primitive.reward_points!r}")


@dc.dataclass
class OutcomeChoiceConfig:
    """How a run whose chooser is "outcome_model" turns its outcome model file's predictions
    into a choice (rl/primitive/outcome/chooser.py); `evaluate --set outcome.*` reaches them."""
    BOUNDS = {"pessimism": ">= 0", "tilt_veto": "(0, 1]"}
    # A candidate's score is its members' mean predicted reward less this many times their
    # standard deviation (the file must hold an ensemble: outcome_model.py fit --members). Why:
    # a model fitted on a few hundred objects is confidently wrong on others, and the highest
    # of hundreds of predictions is mostly the most wrong; on held-out objects' lookahead
    # states 1.0 raised what the choice earned from 0.009 to 0.032 per primitive, but on the
    # 200 unseen push_turn episodes success stayed where one model left it (0.340 against
    # 0.345; docs/results/primitive/, item 38). Hence 0, the mean alone, by default.
    pessimism: float = 0.0
    # Candidates the file's tilt classifier (rl/primitive/outcome/tilt_classifier.py, fit --tilt) gives a
    # probability above this of tipping or rolling the object are not chosen, unless every
    # candidate is. Why: on push_turn a tipped object fails the episode, and the outcome
    # model's choices tipped it a quarter of the time (item 38). Measured on the 200 unseen
    # push_turn episodes: 0.5 / 0.2 gave 0.280 / 0.230 against 0.345 without: the unseen
    # objects' rolls and tips stayed (67 episodes), and pushes the task needed were left out.
    # Hence 1, no veto, by default.
    tilt_veto: float = 1.0
    # Each candidate's predicted reward becomes its expectation under the file's tilt
    # classifier: (1 - p) x the model's reward + p x the mean reward the file's data measured
    # for the candidates that did tip or roll (fit --tilt records it: `tilted_reward`). Why: the
    # outcome model fits tipping and rolling worst of all (item 37), and a hard veto left out
    # pushes the task needed (above); weighing by the probability keeps every candidate. On
    # held-out objects' lookahead states it raised what the choice earned per primitive from
    # 0.012 to 0.035, but on the 200 unseen episodes it lost: push_turn 0.215 against 0.340
    # for the same file without it, full6d 0.035 against 0.065. Every push that can reach the
    # goal can also tip, so the choice turned timid (never touched 25 / 32 episodes against
    # 10 / 11; docs/results/primitive/, item 39). The tilted reward is the collecting task's
    # (push_turn's, for every folder so far). Hence off by default.
    tilt_blend: bool = False


@dc.dataclass
class PrimitiveTrainConfig(RunSettings):
    """A primitive training run (rl/primitive/trainer.py). total_steps counts primitives (one
    env step each); each primitive is followed by `updates_per_step` TD3 updates once the replay
    holds `learning_starts` transitions. TD3 numbers: rl/primitive/td3.py's TD3Settings."""
    BOUNDS = {"replay_capacity": ">= 1", "learning_starts": ">= 1", "updates_per_step": ">= 0",
              "batch_size": ">= 1", "gamma": "(0, 1]", "tau": "(0, 1]", "actor_lr": "> 0",
              "critic_lr": "> 0", "policy_delay": ">= 1", "target_noise": ">= 0",
              "target_noise_clip": ">= 0", "temperature": "> 0", "motion_noise": ">= 0",
              "random_steps": ">= 0", "log_every": ">= 1", "hidden": ">= 1",
              "actor_warmup": ">= 0", "hindsight_goals": ">= 0", "point_locations": ">= 1"}
    policy: str = "primitive"
    # Candidate contact locations: "patch", the encoder's 16 patch centres (each a cloud point)
    # with their tokens, or "point", `point_locations` cloud points spread by farthest-point
    # sampling (the first 16 are the patch centres), each with its nearest patch's token
    # (config/choices.py PRIMITIVE_LOCATIONS has their cost). Measured on push_turn with
    # hindsight goals: 64 points 0.220 against 0.245-0.295 for the patch centres at 3.5x the
    # update time (docs/results/primitive/, item 19), hence "patch" by default.
    locations: str = "patch"
    point_locations: int = 64
    # How evaluation chooses: "critic", the location of highest Q with the actor's motion there;
    # "outcome_model", the candidate (the actor's motion or a fixed bank's, at every location)
    # of highest reward predicted by the run's outcome_model.pt (rl/primitive/outcome/chooser.py), a run
    # folder written by docs/results/primitive/outcome_model.py fit. Measured on the 200 unseen
    # push_turn episodes: 0.330 against the critic's 0.295 (0.245 / 0.130 at rest; item 35).
    # Training (TD3) always explores with the critic's scores.
    chooser: str = "critic"
    # The folder whose checkpoints/ hold this run's actor and critic, when not its own: a
    # shipped outcome-model folder names the sibling weights folder whose actor proposes its
    # motions ("../push_turn_primitive", `corn-drake ship`), so models/weights does not carry
    # the same 1.7 MB twice. Relative to this folder (rl/checkpoints.run_relative_path).
    agent_weights: str = ""
    outcome: OutcomeChoiceConfig = dc.field(default_factory=OutcomeChoiceConfig)
    replay_capacity: int = 200_000
    learning_starts: int = 256
    updates_per_step: int = 1
    batch_size: int = 64
    # Per primitive. 0.9: an episode is at most max_primitives (10) decisions, and a lower
    # discount keeps the bootstrapped values near what the next few primitives earn (0.99 let
    # the values drift above any return the policy obtained: docs/results/primitive/).
    gamma: float = 0.9
    tau: float = 0.005
    actor_lr: float = 3e-4
    critic_lr: float = 3e-4
    policy_delay: int = 2
    # TD3 updates of this run before its actor's first step (rl/td3.TD3Settings.actor_warmup):
    # for a run started --init-from another task's policy, whose critic must re-fit first.
    actor_warmup: int = 0
    target_noise: float = 0.2
    target_noise_clip: float = 0.5
    # Exploration: locations sampled from softmax(score / temperature), motions + N(0, noise).
    temperature: float = 0.1
    motion_noise: float = 0.3
    # Hindsight goals (rl/primitive/hindsight.py, HER's "future" strategy): each finished episode's
    # transitions are stored this many more times, each with a goal the episode reached later,
    # so primitives that turned the object somewhere teach turning. 0: off.
    hindsight_goals: int = 0
    # Whether the pose where an episode left the workspace may be one of those goals. True is
    # how the hindsight runs of docs/results/primitive/ items 13-18 ran: the push that threw
    # the object out then came back as a success in every copy (its only later pose), and those
    # policies ended 29-54 of 200 unseen push_turn episodes out of the workspace (16 without
    # hindsight goals). False: such a pose is never a goal, that push gets no copies. Measured
    # off: 0.260 and still 45 episodes off the table (item 21): the falls come from the pushes,
    # not from these goals. Kept on by default so the earlier runs' commands repeat them.
    hindsight_exit_goals: bool = True
    # The first primitives choose uniformly random locations and motions (fills the replay).
    random_steps: int = 512
    hidden: int = 256
    # A primitive run whose trained actor and critic this run starts from (fresh optimisers,
    # replay and counters; its primitives are not counted in this run's): a curriculum, e.g.
    # the push policy carried on to push_turn. Same locations and network width.
    init_from: str = ""
    log_every: int = 50  # primitives per metrics row / TensorBoard point
    checkpoint_every: int = 500  # primitives between checkpoints (model, optimisers, replay)
    primitive: PrimitiveConfig = dc.field(default_factory=PrimitiveConfig)
    env: TeacherDiagramConfig = dc.field(default_factory=TeacherDiagramConfig)

    def check(self) -> None:
        """InputError naming the first field a run cannot start with (the env's too)."""
        check_bounds(self)  # nested configs too (primitive, env)
        check_reward_points(self.primitive)
        if self.chooser not in PRIMITIVE_CHOOSERS:
            raise InputError(f"chooser must be one of {', '.join(PRIMITIVE_CHOOSERS)}, got "
                             f"{self.chooser!r}")
        if self.locations not in PRIMITIVE_LOCATIONS:
            raise InputError(f"locations must be one of {', '.join(PRIMITIVE_LOCATIONS)}, got "
                             f"{self.locations!r}")
        points = self.env.scene.object.cloud_points
        if self.locations == "point" and self.point_locations > points:
            raise InputError(f"point_locations ({self.point_locations}) must not exceed the "
                             f"cloud's {points} points (env.scene.object.cloud_points)")
        if self.policy != "primitive":
            raise InputError(f"a primitive run's policy must be 'primitive', got {self.policy!r}")
        if self.hindsight_goals and self.primitive.tip_penalty > 0:
            raise InputError(f"hindsight_goals ({self.hindsight_goals}) and primitive.tip_penalty "
                             f"({self.primitive.tip_penalty}) do not go together: relabelled "
                             f"goals do not apply the tipping rule (rl/primitive/hindsight.py)")
        self.env.check()
