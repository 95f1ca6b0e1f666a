"""The contact-primitive policy's configs: how one primitive is executed (PrimitiveConfig, the
executor's and the primitive env's), and what a primitive training run records
(PrimitiveTrainConfig, `corn-drake train --policy primitive`, RUN/config.yaml).

A primitive: a contact location on the object's cloud (a point with its outward surface normal)
and a push motion. The executor (systems/control/primitive_executor.py) moves the tool up to `clearance`
above the object's top, across to above the pre-contact point (`pre_contact_distance` off the
surface along the normal), down to it, pushes by the motion over `push_steps` policy periods and
lifts `retreat_height`. Distances are metres; step counts are policy periods (0.1 s).

No `from __future__ import annotations`: yaml_load_typed needs real types on the fields.
"""

import dataclasses as dc

from corn_drake.config.plumbing.bounds import check_bounds, one_of, relation
from corn_drake.config.choices import PRIMITIVE_CHOOSERS, PRIMITIVE_POLICY
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
    # Range checks (config/plumbing/bounds.py): what check_bounds refuses.
    # Upper bounds: distances within the table's reach (push_distance=1e300 was taken and
    # then failed deep in the planner), counts an episode can play.
    BOUNDS = {"pre_contact_distance": "(0, 0.2]", "clearance": "(0, 0.5]",
              "min_tool_height": "[0, 0.2]", "push_distance": "(0, 0.5]", "push_steps": "[1, 100]",
              "retreat_height": "[0, 0.5]", "retreat_steps": "[1, 100]",
              "reach_tolerance": "(0, 0.1]", "turn_tolerance": "(0, 3.1416]",
              "approach_steps": "[1, 1000]", "max_primitives": "[1, 1000]",
              "stiffness": "[-1, 1]", "damping": "[-1, 1]",
              "progress_reward": ">= 0", "push_height": ">= 0", "finger_tilt_deg": "[0, 60]",
              "rest_linear_speed": "> 0", "rest_angular_speed": "> 0",
              "settle_steps": ">= 0", "settle_motion": "> 0"}
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
    # (the primitive results log, item 37). 0: no waiting (shipped cards replay as they were).
    settle_steps: int = 0
    settle_motion: float = 0.002
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
    # bonus over a 10-primitive episode. (Other reward terms, a turn reward, tip and exit
    # penalties and the goal flow of the surface cloud, measured worse: config/retired.py.)
    progress_reward: float = 10.0
    # Side pushes aim this high above the table (m; the tool point), lowered from the chosen
    # contact point as far as the object's cloud leaves room for the fingers
    # (systems/control/low_push.py: a push at mid-height tips an upright bottle or a tall box, one near
    # the table slides it). 0: push at the chosen point's own height. 0.02: what the shipped
    # push_turn_primitive and full6d_outcome ran with (the primitive results log, items 10, 15).
    push_height: float = 0.02
    # For a side contact the fingers lean this far (degrees) from vertical toward the surface,
    # the palm away from it (systems/primitive_executor.facing_rotation: with vertical fingers
    # the palm, 2.1 cm deeper than they are, meets a tall object first, 4.5-10 cm above the
    # tool point, and the push tips it). Only where the object's top reaches the palm's lower
    # edge at the pre-contact point (flat objects keep vertical fingers). 0: vertical fingers.
    # 30: as push_height, the shipped runs' lean.
    finger_tilt_deg: float = 30.0
    # Success only at rest: the task's success counts when a primitive has ended (the executor
    # idle again, the hand lifted off) with the object within the task's tolerances and still
    # (under rest_linear_speed m/s and rest_angular_speed rad/s), not at the period the object
    # passes through the goal pose mid-push. Why: the paper's rule (checked every policy
    # period, no stillness check) counts a pose the object flies through: 15 of the shipped
    # push_turn policy's 16 successes on 46 unseen episodes ended mid-push, the object turning
    # at up to 6.4 rad/s (the primitive results log, item 33). Off by default: the task's own
    # rule, the one every report here uses. With hindsight_goals a relabelled success needs the
    # object still too (the observation's object_speed, rl/primitive/hindsight.py).
    success_at_rest: bool = False
    rest_linear_speed: float = REST_LINEAR_SPEED
    rest_angular_speed: float = REST_ANGULAR_SPEED


@dc.dataclass
class PrimitiveTrainConfig(RunSettings):
    """A primitive training run (rl/training/primitive_trainer.py). total_steps counts primitives
    (one env step each); each primitive is followed by `updates_per_step` TD3 updates once the replay
    holds `learning_starts` transitions. The TD3 numbers are set here only
    (rl/primitive/td3.TD3Settings.for_run reads them)."""
    # replay_capacity's bound: ~20 KB per transition (the 16 locations' tokens and features, now
    # and next), so a million is ~20 GB at most (np.zeros pages in lazily; 1e12 was a
    # MemoryError after the config was written); hidden: 4096 is 16x the shipped 256; a batch
    # of 65536 transitions; 64 hindsight goals per transition (each one more stored copy).
    BOUNDS = {"replay_capacity": "[1, 1000000]", "learning_starts": ">= 1",
              "updates_per_step": ">= 0",
              "batch_size": "[1, 65536]", "gamma": "(0, 1]", "tau": "(0, 1]", "actor_lr": "> 0",
              "critic_lr": "> 0", "policy_delay": ">= 1", "target_noise": ">= 0",
              "target_noise_clip": ">= 0", "temperature": "> 0", "motion_noise": ">= 0",
              "random_steps": ">= 0", "log_every": ">= 1", "hidden": "[1, 4096]",
              "hindsight_goals": "[0, 64]",
              "policy": one_of((PRIMITIVE_POLICY,)), "chooser": one_of(PRIMITIVE_CHOOSERS),
              # Run folders: rl/checkpoints resolves and loads them, naming the field.
              "agent_weights": "text", "init_from": "text"}
    # A replay smaller than learning_starts never starts learning, and one smaller than a batch
    # cannot hold one (replay_capacity=4 "trained" 320 primitives without a critic update).
    RELATIONS = (
        relation("learning_starts", "<= {replay_capacity}", lambda start, cap: start <= cap,
                 "replay_capacity"),
        relation("batch_size", "<= {replay_capacity}", lambda batch, cap: batch <= cap,
                 "replay_capacity"),
        # With no update before learning_starts, a shorter run saved an untrained policy as
        # trained (issue 63); one that starts from trained weights (init_from) may be short.
        relation("total_steps", "> {learning_starts} (no update happens before it) unless "
                 "{init_from} names trained weights", lambda steps, start, init: steps > start
                 or bool(init), "learning_starts", "init_from"),
    )
    policy: str = "primitive"
    # How evaluation chooses: "critic", the location of highest Q with the actor's motion there;
    # "outcome_model", the candidate (the actor's motion or a fixed bank's, at every location)
    # of highest reward predicted by the run's outcome_model.pt (rl/primitive/outcome/chooser.py), a run
    # folder written by `corn-drake fit-outcome`. Measured on the 200 unseen
    # push_turn episodes: 0.330 against the critic's 0.295 (0.245 / 0.130 at rest; item 35).
    # Training (TD3) always explores with the critic's scores. "critic" by default although the
    # shipped full6d_outcome folder chooses by its model: a run folder chooses by an outcome
    # model only once one has been fitted to its own collected outcomes and written beside its
    # weights (outcome_model.pt), which a training run does not do, so every run `train` writes
    # would otherwise fail to load.
    chooser: str = "critic"
    # The folder whose checkpoints/ hold this run's actor and critic, when not its own: a
    # shipped outcome-model folder names the sibling weights folder whose actor proposes its
    # motions ("../push_turn_primitive", `corn-drake ship`), so models/weights does not carry
    # the same 1.7 MB twice. Relative to this folder (rl/checkpoints.run_relative_path).
    agent_weights: str = ""
    replay_capacity: int = 200_000
    learning_starts: int = 256
    updates_per_step: int = 1
    batch_size: int = 64
    # Per primitive. 0.9: an episode is at most max_primitives (10) decisions, and a lower
    # discount keeps the bootstrapped values near what the next few primitives earn (0.99 let
    # the values drift above any return the policy obtained: the primitive results log).
    gamma: float = 0.9
    tau: float = 0.005
    actor_lr: float = 3e-4
    critic_lr: float = 3e-4
    policy_delay: int = 2
    target_noise: float = 0.2
    target_noise_clip: float = 0.5
    # Exploration: locations sampled from softmax(score / temperature), motions + N(0, noise).
    temperature: float = 0.1
    motion_noise: float = 0.3
    # Hindsight goals (rl/primitive/hindsight.py, HER's "future" strategy): each finished episode's
    # transitions are stored this many more times, each with a goal the episode reached later,
    # so primitives that turned the object somewhere teach turning. 0: off. 4: the shipped
    # runs' (the primitive results log, items 13-15).
    hindsight_goals: int = 4
    # The first primitives choose uniformly random locations and motions (fills the replay).
    random_steps: int = 512
    hidden: int = 256
    # A primitive run whose trained actor and critic this run starts from (fresh optimisers,
    # replay and counters; its primitives are not counted in this run's): a curriculum, e.g.
    # the push policy carried on to push_turn. Same network width.
    init_from: str = ""
    log_every: int = 50  # primitives per metrics row / TensorBoard point
    checkpoint_every: int = 500  # primitives between checkpoints (model, optimisers, replay)
    primitive: PrimitiveConfig = dc.field(default_factory=PrimitiveConfig)
    env: TeacherDiagramConfig = dc.field(default_factory=TeacherDiagramConfig)

    def check(self) -> None:
        """InputError naming the first field a run cannot start with (the env's too)."""
        check_bounds(self)  # nested configs too (primitive, env)
        if self.chooser not in PRIMITIVE_CHOOSERS:
            raise InputError(f"chooser must be one of {', '.join(PRIMITIVE_CHOOSERS)}, got "
                             f"{self.chooser!r}")
        if self.policy != "primitive":
            raise InputError(f"a primitive run's policy must be 'primitive', got {self.policy!r}")
        self.env.check()
