"""Typed configs for the diagrams in diagrams/*.yaml, loaded with pydrake's yaml_load_typed.

Unknown keys are an error (yaml_load_typed's default), reported with the file's path.
Numbers default to the paper's / official code's values (see ../shared/DESIGN.md spec sheet).
No `from __future__ import annotations` here: yaml_load_typed needs real types on the fields.
"""


import copyreg
import dataclasses as dc
import typing
from pathlib import Path
from typing import Any, TypeVar

from pydrake.multibody.plant import MultibodyPlantConfig

from corn_drake.errors import InputError, MissingInputError
from corn_drake.tasks.specs import Full6dGoal, GoalSpec

T = TypeVar("T")


def _plant_config() -> MultibodyPlantConfig:
    return MultibodyPlantConfig(
        # 80 Hz physics / 10 Hz policy as in the paper; tests/test_scene_physics.py checks
        # resting and pushing stability at this step.
        time_step=0.0125,
        discrete_contact_approximation="sap",
        contact_model="hydroelastic_with_fallback",
        # Unsampled output ports: every system that updates at a policy boundary t_k (IK latch,
        # reward hold) then sees the plant state at t_k. With sampled ports (Drake's default)
        # they saw the state one physics step later, because the plant's own update at t_k had
        # already been computed (tests/test_reward.py checks the hold).
        use_sampled_output_ports=False)


@dc.dataclass
class PhysicsConfig:
    # Drake's own plant settings (time step, contact model and approximation, ...), passed as
    # they are to AddMultibodyPlant (scene/builder.py). In YAML: physics: {plant: {...}}.
    plant: MultibodyPlantConfig = dc.field(default_factory=_plant_config)
    policy_period: float = 0.1
    # Used when the object is the compliant side: 1e7 Pa blew up at 12.5 ms in probes, 1e6
    # kicked a resting box 2.5 mm on its first step, 1e5 rested within 0.3 mm.
    object_hydroelastic_modulus: float = 1.0e5
    # Which side of object-table contact is compliant: "object" (compliant hulls on a rigid
    # table) or "table" (rigid hulls on a compliant table). Thin hulls (plates, books) made
    # compliant blew up at 12.5 ms (21 of 24 drops of a 1.5 cm plate); with a 1e6 Pa table,
    # 3 of 24 failed and resting objects stay within 0.3 mm (1e5: 2.8 mm sink; 1e7: more
    # drop failures). The table being compliant keeps every object's contact a patch.
    compliant_body: str = "table"
    table_hydroelastic_modulus: float = 1.0e6
    table_resolution_hint: float = 0.02
    object_hunt_crossley_dissipation: float = 5.0
    # Reflected rotor inertia and damping from the authors' system identification.
    armature: list[float] = dc.field(
        default_factory=lambda: [0.192, 0.54, 0.128, 0.172, 0.15, 0.08, 0.06])
    gravity_on_robot: bool = False

    # The physics step is the plant's. This property (no field: the YAML loader and dumper see
    # only plant.time_step) keeps `physics.time_step` readable and settable for the policy
    # clock, the energy meter and the stable-pose drops.
    @property
    def time_step(self) -> float:
        return self.plant.time_step

    @time_step.setter
    def time_step(self, value: float) -> None:
        self.plant.time_step = value


def _from_yaml(schema, text: str):
    from pydrake.common.yaml import yaml_load_typed

    return yaml_load_typed(schema=schema, data=text)


def _reduce_as_yaml(value):
    from pydrake.common.yaml import yaml_dump_typed

    return _from_yaml, (type(value), yaml_dump_typed(value))


def pickle_as_yaml(schema) -> None:
    """Lets instances of one of Drake's config structs pickle, as their YAML (the text a run's
    config.yaml holds for them): Drake's structs do not pickle, and Ray ships configs to its
    workers (rl/ray_workers.py)."""
    copyreg.pickle(schema, _reduce_as_yaml)


pickle_as_yaml(MultibodyPlantConfig)


OBJECT_KINDS = ("box", "cylinder", "library")
LIBRARY_OBJECTS = ("one", "train")


@dc.dataclass
class ObjectConfig:
    # "box" | "cylinder": a primitive built in code; "library": objects from a library folder.
    kind: str = "box"
    size: list[float] = dc.field(default_factory=lambda: [0.09, 0.07, 0.05])  # box x,y,z
    radius: float = 0.04  # cylinder radius
    length: float = 0.08  # cylinder length
    library: str = ""  # folder holding manifest.json (kind: library)
    # Which of the library's objects (kind: library): "one", the object `object_id`, for the
    # whole run; "train", every train object of the library, each env taking the next one
    # every episode in seeded rounds (rl/vec_env.cycle_object), as `train --objects` sets.
    library_objects: str = "one"
    object_id: str = ""  # id in the library's manifest (library_objects: one)
    mass: float = 0.3
    cloud_points: int = 512

    def check(self) -> None:
        """InputError naming the field where kind, library, library_objects and object_id do
        not name objects; every reader calls it before it builds or lists anything."""
        if self.kind not in OBJECT_KINDS:
            raise InputError(f"scene.object.kind must be one of {', '.join(OBJECT_KINDS)}, "
                             f"got {self.kind!r}")
        if self.kind != "library":
            return
        if not self.library:
            raise InputError("scene.object.library is empty: kind library needs the library "
                             "folder")
        if self.library_objects not in LIBRARY_OBJECTS:
            raise InputError(f"scene.object.library_objects must be one of "
                             f"{', '.join(LIBRARY_OBJECTS)}, got {self.library_objects!r}")
        if self.library_objects == "one" and not self.object_id:
            raise InputError(f"scene.object.object_id is empty: name one object of library "
                             f"{self.library}, or set library_objects: train for all its train "
                             "objects")
        if self.library_objects == "train" and self.object_id:
            raise InputError(f"scene.object.object_id {self.object_id!r} with library_objects: "
                             "train (every train object): give one or the other")

    @property
    def cycles_library(self) -> bool:
        """True when the envs go through every train object of `library` (checked first)."""
        self.check()
        return self.kind == "library" and self.library_objects == "train"


@dc.dataclass
class RandomizationConfig:
    enabled: bool = True
    mass: list[float] = dc.field(default_factory=lambda: [0.1, 0.5])
    # Rescale each episode's object to a radius (m) drawn from [low, high]; absent (null), the
    # object keeps its own size (library objects are sized when the library is built).
    object_radius: typing.Optional[list[float]] = None
    object_friction: list[float] = dc.field(default_factory=lambda: [0.7, 1.0])
    table_friction: list[float] = dc.field(default_factory=lambda: [0.3, 0.8])
    finger_friction: list[float] = dc.field(default_factory=lambda: [1.0, 1.5])
    # Drake's SAP contact is inelastic: restitution is sampled and reported to the policy as in
    # the paper but has no physical effect here.
    restitution: list[float] = dc.field(default_factory=lambda: [0.0, 0.2])
    # Std of N(0, s) joint-torque noise (N m) per physics step. The authors add it only for the
    # student / phase-2 fine-tuning, so the teacher diagram sets 0.
    torque_noise_std: float = 0.0


@dc.dataclass
class ControllerConfig:
    max_position_delta: float = 0.06  # m, residual EE translation at |a| = 1
    max_rotation_delta: float = 0.1  # rad, residual axis-angle at |a| = 1
    kp_range: list[float] = dc.field(default_factory=lambda: [10.0, 200.0])
    rho_range: list[float] = dc.field(default_factory=lambda: [0.1, 2.0])
    ik_damping: float = 0.01  # dq = J^T (J J^T + ik_damping I)^-1 e
    ee_clamp: float = 0.1  # target within +- this of the current EE position
    object_margin: float = 0.2  # target within object position +- (radius + margin)
    effort_limits: list[float] = dc.field(
        default_factory=lambda: [87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0])
    # "symbolic": the torque law compiled into a C++ SymbolicVectorSystem (fast);
    # "python": the same law in a Python LeafSystem (see systems/impedance_controller.py).
    torque_backend: str = "symbolic"


@dc.dataclass
class TaskConfig:
    # The task's name, reported by `evaluate` and in a run's config (diagrams/tasks/NAME.yaml).
    name: str = "full6d"
    episode_steps: int = 300
    success_position: float = 0.05  # planar xy error, m
    # Whether success also needs the orientation error within success_orientation (the paper's
    # task); false: the xy error alone decides (diagrams/tasks/push.yaml says why).
    check_orientation: bool = True
    success_orientation: float = 0.1  # rad
    # What the goal is and how the object's start and goal are drawn: one of the variants in
    # corn_drake/tasks/specs.py, chosen in YAML by its tag (`goal: !PlanarGoal {...}`).
    goal: GoalSpec = dc.field(default_factory=Full6dGoal)
    # Goal region (xy, m; official code): every variant's goal lies inside it.
    goal_x: list[float] = dc.field(default_factory=lambda: [-0.16, 0.16])
    goal_y: list[float] = dc.field(default_factory=lambda: [-0.2, 0.2])
    # Object centre outside this box ends the episode (official workspace bounds).
    workspace_low: list[float] = dc.field(default_factory=lambda: [-0.5, -0.55, 0.2])
    workspace_high: list[float] = dc.field(default_factory=lambda: [0.5, 0.55, 0.9])
    robot_init_low: list[float] = dc.field(
        default_factory=lambda: [-0.3, -0.4636, -0.2, -2.7432, -0.3335, 1.5269, -1.5707963])
    robot_init_high: list[float] = dc.field(
        default_factory=lambda: [0.3, 0.5432, 0.2, -1.5237, 0.3335, 2.5744, 1.5707963])
    robot_init_noise: float = 0.03
    # Reward (potential-based, official code): k1 * 0.995^(k2 * dist).
    keypoint_k1: float = 0.302
    keypoint_k2: float = 243.12
    hand_k1: float = 0.0604
    hand_clip: float = 0.5
    potential_gamma: float = 0.995
    success_reward: float = 1.0
    energy_coef: float = 1.0e-4


@dc.dataclass
class SceneConfig:
    physics: PhysicsConfig = dc.field(default_factory=PhysicsConfig)
    object: ObjectConfig = dc.field(default_factory=ObjectConfig)
    table_size: list[float] = dc.field(default_factory=lambda: [0.4, 0.5, 0.4])
    robot_base: list[float] = dc.field(default_factory=lambda: [-0.5, 0.0, 0.4])


@dc.dataclass
class TeacherDiagramConfig:
    scene: SceneConfig = dc.field(default_factory=SceneConfig)
    randomization: RandomizationConfig = dc.field(default_factory=RandomizationConfig)
    controller: ControllerConfig = dc.field(default_factory=ControllerConfig)
    task: TaskConfig = dc.field(default_factory=TaskConfig)
    seed: int = 0

    def check(self) -> None:
        """InputError naming the first field no episode could be built from (object, size
        randomization, task ranges). Commands call it before they write a run's config, so a
        bad value is refused up front instead of failing the run at its first reset."""
        from corn_drake.scene.randomization import check_randomization
        from corn_drake.tasks.sampling import check_task

        self.scene.object.check()
        check_randomization(self.randomization)
        check_task(self.task)


@dc.dataclass
class PPOConfig:
    """PPO settings; where each default comes from (paper = Table "Hyperparameters for PPO" of
    the CORN paper, code = the authors' models/rl/v6/ppo.py with cloud_arm_mlp_base.yaml, see
    shared/reference/corn_official_code.md section 4):

    gamma 0.99, gae_lambda 0.95, clip 0.3, epochs 8, lr 3e-4, kl_target 0.016: paper and code.
    kl_stop_factor 1.5: the paper's early-stopping KL target 0.024 = 1.5 x 0.016 (code: the
    same, the first minibatch of an update exempt). lr_min 1e-6, lr_max 1e-2 and the x1.5 / /1.5
    steps of the adaptive lr: code. minibatches 1: code (chunk_size 1, the whole rollout).
    policy_coef 0.5, value_coef 2.0: code (k_pi 0.5, k_val 2.0, and its value loss is
    0.5 * MSE, as ours). The paper's table prints "policy 2, value 0.5": the code's numbers
    with the names swapped; we follow the code, which produced the paper's results.
    bound_coef 0.02: paper and code; bound_limit 1.1 and max_grad_norm 1.0: code.
    Entropy bonus 0 (paper and code): none is implemented.

    separate_critic, critic_lr: ours, off by default (the authors share the trunk). With it the
    value comes from a second head of the same shape on the same (detached) encoder features,
    trained by its own Adam at the fixed critic_lr on every minibatch of every epoch, whatever
    the policy's KL does, with its gradient clipped on its own. Why: at our 1-2k-transition
    batches the KL rule holds the shared lr near 1e-5 and stops updates after 1-4 steps, so a
    shared critic never fits the returns (docs/results/README.md, the one-step PPO probe).
    fan_in_lr_ref: ours, 0 (off) by default. > 0 scales the lr of each weight tensor by
    min(1, fan_in_lr_ref / its fan-in) (rl/ppo.py fan_in_groups says why).
    """

    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip: float = 0.3
    epochs: int = 8
    minibatches: int = 1
    lr: float = 3e-4
    lr_min: float = 1e-6
    lr_max: float = 1e-2
    kl_target: float = 0.016
    kl_stop_factor: float = 1.5
    policy_coef: float = 0.5
    value_coef: float = 2.0  # x 0.5 * (V - R)^2 in PPO.losses, as the authors' k_val
    bound_coef: float = 0.02
    bound_limit: float = 1.1
    max_grad_norm: float = 1.0
    separate_critic: bool = False
    critic_lr: float = 3e-4
    fan_in_lr_ref: int = 0


@dc.dataclass
class TrainConfig:
    policy: str = "state"
    total_steps: int = 20_000  # environment steps (transitions) over all envs
    workers: int = 0  # 0: envs in this process; > 0: Ray actors
    envs_per_worker: int = 4
    rollout_steps: int = 32  # per env and update
    seed: int = 0
    checkpoint_every: int = 5  # updates
    # Keep a copy of the checkpoint as checkpoints/step_NNNNNNNNN.pt each time training passes
    # a multiple of this many env steps (0: none). last.pt is overwritten; the copies let a
    # comparison evaluate every run at the same wall-clock (`evaluate --checkpoint`).
    snapshot_every: int = 0
    # A finished run whose trained agent (weights, log-std, observation normalisers) this run
    # starts from, with a fresh optimiser, reward scaler and step count: a curriculum, e.g. the
    # push teacher carried on to push_turn. Same policy, encoder and network shape; the
    # source's log-std replaces init_log_std. Its env steps are not counted in this run's.
    init_from: str = ""
    ray_address: str = ""
    encoder: str = ""  # frozen encoder checkpoint for corn / pn
    # Train on an encoder whose recorded contact F1 is below rl/encoders.MIN_CONTACT_F1 (the
    # demo's tiny pretraining, smoke tests); recorded so evaluate accepts the run too.
    allow_weak_encoder: bool = False
    # Initial log-std of the Gaussian policy: 0 as in the paper; the reduced benchmark starts
    # lower, since at std 1 every step jitters the hand by most of max_position_delta and a
    # run of a few 100k steps cannot shrink it (Adam moves it ~lr per optimiser step).
    init_log_std: float = 0.0
    # Normalise the encoder's features (corn/e2e tokens, the pn global feature) per dimension by
    # a running mean/std before the policy head, as the context is. Ours, off by default (the
    # authors normalise every non-constant observation by running statistics; whether that
    # includes the embedding is not stated). Measured: the frozen tokens' attended features
    # have per-dimension means larger than their spread; normalising them cut the policy's move
    # under one sign step of lr 1e-5 from KL 0.031 to 0.019, not enough to change how PPO
    # behaves, and no learning gain was measured (docs/results/README.md).
    normalize_features: bool = False
    # Torch device of the learner (agent, batched inference, PPO update): "cpu", "cuda" or
    # "cuda:N". Envs, observations and actions stay numpy on the CPU either way, and
    # checkpoints hold CPU tensors, so a run may resume on another device.
    device: str = "cpu"
    ppo: PPOConfig = dc.field(default_factory=PPOConfig)
    env: TeacherDiagramConfig = dc.field(default_factory=TeacherDiagramConfig)



@dc.dataclass
class PretrainConfig:
    """Contact pretraining (paper: AdamW 2e-4, wd 5e-4, batch 1024, cosine schedule + warm-up)."""
    model: str = "corn"  # corn | pointnet
    steps: int = 2000
    batch_size: int = 1024
    lr: float = 2e-4
    min_lr: float = 1e-6
    weight_decay: float = 5e-4
    warmup_steps: int = 100
    max_grad_norm: float = 4.0
    # Augmentation (train split only): yaw about the cloud centroid, translation, point noise.
    translate_std: float = 0.04  # m (0.1 in normalised units)
    point_noise_std: float = 0.004  # m (0.01 in normalised units)
    eval_every: int = 250
    checkpoint_every: int = 250
    eval_samples: int = 4096
    seed: int = 0


def load_config(path: str | Path, schema: type[T], defaults: T | None = None) -> T:
    """Loads a YAML file into `schema`, on top of `defaults` when given (a layer: the file names
    only what differs); a missing file, bad YAML, an unknown key or a value of the wrong type
    raises an InputError naming the file (and the field, where there is one)."""
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"config file not found: {path}")
    return _load_typed(schema, str(path), defaults, filename=str(path))


def load_config_string(text: str, schema: type[T], name: str = "<string>",
                       defaults: T | None = None) -> T:
    """As load_config for YAML text; `name` says where the text came from in errors."""
    return _load_typed(schema, name, defaults, data=text)


def config_fields(cfg) -> dict[str, Any]:
    """A typed config as {'a.b.c': value} of plain YAML values, through the same dump the run's
    config.yaml is written with (so Drake's config structs flatten too, and floats compare as
    the file holds them)."""
    from pydrake.common.yaml import yaml_dump_typed

    def flat(value, prefix):
        if not isinstance(value, dict):
            return {prefix: value}
        out = {}
        for key, item in value.items():
            out.update(flat(item, f"{prefix}.{key}" if prefix else str(key)))
        return out

    return flat(read_tagged_yaml(yaml_dump_typed(cfg)), "")


class TaggedMapping(dict):
    """A YAML mapping that carried a type tag (Drake's variants: `focal: !FovDegrees {y: 50}`,
    `goal: !PlanarGoal {...}`); flattened by config_fields as a `!` entry beside the fields."""

    def __init__(self, tag: str, items):
        super().__init__(items)
        self["!"] = tag


def _tagged_loader():
    import yaml

    class Loader(yaml.SafeLoader):
        pass

    def construct(loader, tag, node):
        if isinstance(node, yaml.MappingNode):
            return TaggedMapping(tag, loader.construct_mapping(node, deep=True))
        return TaggedMapping(tag, {})  # `!Tag` alone, or `!Tag ''`: a variant with defaults

    Loader.add_multi_constructor("!", construct)
    return Loader


def _tagged_dumper():
    import yaml

    class Dumper(yaml.SafeDumper):
        pass

    def represent(dumper, data):
        fields = {k: v for k, v in data.items() if k != "!"}
        return dumper.represent_mapping("!" + data["!"], fields)

    Dumper.add_representer(TaggedMapping, represent)
    return Dumper


def read_tagged_yaml(text: str):
    """YAML text as plain data, keeping Drake's variant tags (TaggedMapping) where yaml.safe_load
    would refuse them."""
    import yaml

    return yaml.load(text, Loader=_tagged_loader())  # noqa: S506 (a SafeLoader subclass)


def dump_tagged_yaml(data) -> str:
    """The inverse of read_tagged_yaml: tags written back in front of their mappings."""
    import yaml

    return yaml.dump(data, Dumper=_tagged_dumper(), sort_keys=False)


def field_types(schema) -> dict[str, Any] | None:
    """{field name: type} of a config schema, a dataclass or one of Drake's bound config structs
    (MultibodyPlantConfig lists its fields in __fields__); None for anything else."""
    if dc.is_dataclass(schema):
        return typing.get_type_hints(schema)
    fields = getattr(schema, "__fields__", None)
    if isinstance(fields, tuple) and all(hasattr(f, "name") for f in fields):
        return {f.name: f.type for f in fields}
    return None


# What drake's yaml_load_typed raises for a value the schema cannot take: RuntimeError names
# the key; a scalar it cannot convert leaks a bare ValueError/TypeError; a scalar where a
# mapping belongs fails one of its asserts.
_LOAD_ERRORS = (RuntimeError, ValueError, TypeError, AssertionError)


def _load_typed(schema: type[T], name: str, defaults: T | None = None, **source) -> T:
    from pydrake.common.yaml import yaml_load_typed
    import yaml

    try:
        if defaults is None:
            return yaml_load_typed(schema=schema, **source)
        return yaml_load_typed(schema=schema, defaults=defaults, **source)
    except UnicodeDecodeError:
        raise InputError(f"invalid config {name}: not a UTF-8 text file") from None
    except yaml.YAMLError as e:
        raise InputError(f"invalid config {name}: not valid YAML ({_one_line(e)})") from e
    except RuntimeError as e:
        raise InputError(f"invalid config {name}: {_one_line(e)}") from e
    except _LOAD_ERRORS as e:
        text = source["data"] if "data" in source else Path(source["filename"]).read_text()
        found = _failing_field(schema, read_tagged_yaml(text))
        # drake's asserts carry only the offending value as their message.
        detail = "wrong type" if isinstance(e, AssertionError) else _one_line(e)
        if found is None:
            raise InputError(f"invalid config {name}: {detail}") from e
        field, value = found
        raise InputError(f"invalid config {name}: field {field} = {value!r}: {detail}") from e


def _failing_field(schema: type, data, path: str = "") -> tuple[str, object] | None:
    """(dotted name, value) of the first field of `data` (found at `path`) that `schema` cannot
    load, found by loading one field at a time with drake's loader, so the verdict is its own."""
    from pydrake.common.yaml import yaml_load_typed
    import yaml

    if not isinstance(data, dict):
        return (path, data) if path else None
    types = field_types(schema) or {}
    for key, value in data.items():
        if key not in types:
            continue  # an unknown key fails with drake's own RuntimeError naming it
        try:
            yaml_load_typed(schema=schema, data=dump_tagged_yaml({key: value}))
        except _LOAD_ERRORS:
            name = f"{path}.{key}" if path else str(key)
            field_type = types[key]
            if typing.get_origin(field_type) is typing.Union:  # a tagged variant (task.goal)
                variants = {v.__name__: v for v in typing.get_args(field_type)}
                tag = value.get("!") if isinstance(value, dict) else None
                field_type = variants.get(tag, typing.get_args(field_type)[0])
            if field_types(field_type) is not None:
                return _failing_field(field_type, value, name) or (name, value)
            return name, value
    return None


def _one_line(error: Exception) -> str:
    return " ".join(str(error).split())
