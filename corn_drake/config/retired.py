"""Settings that were removed after they measured no gain (issue 52), so a user's old run folder
or `--set` naming one is told so in one line instead of drake's "unknown key".

RETIRED maps (config class name, field name) to why it went: the measurement that retired it.
`refuse_retired(schema, data, name)` walks YAML data the way the loader will read it into
`schema` and raises an InputError at the first retired key it meets.
"""

import typing

from corn_drake.config.plumbing.yaml_io import field_types
from corn_drake.errors import InputError

# Each entry: the field as it stood, and the measurement that removed it (the project's own
# reports; experiments/LOG.md and, for "item N", experiments/primitive_policy/LOG.md have the
# rows).
RETIRED: dict[tuple[str, str], str] = {
    # The primitive env's reward terms and the executor's options (the primitive results log).
    ("PrimitiveConfig", "turn_reward"):
        "a turning reward term: 0.010 success on push_turn against 0.185 without (item 12)",
    ("PrimitiveConfig", "tip_penalty"):
        "a tipping penalty: 0.025 success on push_turn against 0.165 without (item 5)",
    ("PrimitiveConfig", "exit_penalty"):
        "a penalty for leaving the table: 0.220 success on push_turn against 0.260 without "
        "(item 22)",
    ("PrimitiveConfig", "keep_on_table"):
        "pushes shortened at the table's edge: 0.220 against 0.295 on push_turn, 0.035 against "
        "0.050 on full6d (items 27, 28)",
    ("PrimitiveConfig", "table_margin"):
        "keep_on_table's margin, retired with it: 0.220 against 0.295 on push_turn (item 27)",
    ("PrimitiveConfig", "tilt_stop_deg"):
        "a push stopped once the object tilts: 0.365 / 0.355 against 0.355, within noise "
        "(item 38)",
    ("PrimitiveConfig", "vertical_push"):
        "the push's vertical part scaled down: 0.335 / 0.330 against 0.355 at 1 (item 38); "
        "pushes are always full 3-D",
    ("PrimitiveConfig", "reward_points"):
        "the progress reward on cloud points: 0.225 against 0.245-0.295 on the box keypoints "
        "(item 20); the keypoints are the only reward points",
    ("PrimitiveTrainConfig", "locations"):
        "cloud points as candidate locations: 0.220 against 0.245-0.295 for the patch centres "
        "at 3.5x the update time (item 19); the patch centres are the only locations",
    ("PrimitiveTrainConfig", "point_locations"):
        "the count of cloud-point locations, retired with them: 0.220 against 0.245-0.295 "
        "(item 19)",
    ("PrimitiveTrainConfig", "actor_warmup"):
        "the actor frozen while the critic re-fits: 0.085 success on push_turn against 0.165 "
        "(item 11)",
    ("PrimitiveTrainConfig", "hindsight_exit_goals"):
        "off-table poses kept out of the hindsight goals: 0.260 against 0.255 with them "
        "(item 21); they are always goals",
    # The outcome chooser's ways past the mean prediction (the primitive results log, items
    # 38-39): one section, its three settings retired together.
    ("PrimitiveTrainConfig", "outcome"):
        "its settings measured no gain on the 200 unseen push_turn episodes: pessimism over an "
        "ensemble 0.340 against 0.345, tilt_veto 0.280 / 0.230 against 0.345, tilt_blend 0.215 "
        "against 0.340 (items 38, 39); the chooser takes the one model's predicted reward",
    # PPO options (the results page).
    ("PPOConfig", "fan_in_lr_ref"):
        "a per-layer lr scaled by fan-in: not the fix, push_corn_fan128 went 0.16 -> 0.08 and "
        "was stopped (the one-step PPO probe)",
    ("TrainConfig", "normalize_features"):
        "the encoder's features normalised per dimension: one sign step's KL 0.031 -> 0.019, "
        "and no learning gain measured (push_corn_fn 0.07 / 0.13 / 0.17 at 10k / 30k / 32k, "
        "stopped)",
    # Pinning rollout workers to cores (docs/many_core.md): a RunSettings field, so every run
    # config that had it.
    **{(schema, "pin_workers"):
       "workers pinned to cores: no difference that survived a rerun (bench cores 0.57 -> 0.64, "
       "then 0.63 -> 0.57; docs/many_core.md)"
       for schema in ("TrainConfig", "DistillConfig", "PrimitiveTrainConfig")},
}


def retired_reason(schema, key: str) -> str | None:
    """Why `key` of config class `schema` was retired, or None where it was not."""
    name = getattr(schema, "__name__", None)
    return RETIRED.get((name, key)) if name else None


def retired_message(where: str, key: str, reason: str) -> str:
    return (f"{where}: {key} was retired ({reason}); remove it (a folder recorded with it still "
            "loads once the key is deleted from its config.yaml)")


def refuse_retired(schema, data, name: str, path: str = "") -> None:
    """InputError naming the first key of `data` (YAML read for `schema`, from `name`) that is
    a retired field."""
    if not isinstance(data, dict):
        return
    types = field_types(schema) or {}
    for key, value in data.items():
        dotted = f"{path}.{key}" if path else str(key)
        reason = retired_reason(schema, key)
        if reason is not None and key not in types:
            raise InputError(retired_message(name, dotted, reason))
        field_type = types.get(key)
        if field_type is None:
            continue
        if typing.get_origin(field_type) is typing.Union:  # a tagged variant (task.goal)
            variants = {v.__name__: v for v in typing.get_args(field_type)}
            tag = value.get("!") if isinstance(value, dict) else None
            field_type = variants.get(tag, typing.get_args(field_type)[0])
        if field_types(field_type) is not None:
            refuse_retired(field_type, value, name, dotted)
