"""The closed sets of names a config field takes and a command-line flag offers as `choices`.

Kept apart from the configs that check them (student.py, training.py import pydrake): building
the `corn-drake` parser reads these names, and it must import no Drake or torch, so that
`corn-drake --help` and an argument error answer at once (tests/test_cli_startup.py).
"""

CAMERA_MODES = ("fixed", "tracking")
SEGMENTATION_MODES = ("geometric", "ground_truth")
# What the student executes of its own action in DAgger: the Gaussian's mean or a sample of it.
STUDENT_ACTIONS = ("mean", "sample")
# The student's parameter groups, for freezing (DistillConfig.frozen) and for saying what DAgger
# trains (nn/student.py). The first three come from the contact-pretrained encoder.
STUDENT_PRETRAINED_GROUPS = ("patch_tokenizer", "hand_token", "transformer")
STUDENT_PARAMETER_GROUPS = (*STUDENT_PRETRAINED_GROUPS, "task_tokens", "cross_attention", "gru",
                            "actor")
# The teacher policy variants (rl/policy_kinds.py says what each is) and the contact-primitive
# policy: TrainConfig.policy is one of them.
POLICY_KINDS = ("corn", "e2e", "state", "pn", "p2v-lite", "rot")
PRIMITIVE_POLICY = "primitive"
# Which side of object-table contact is compliant (PhysicsConfig.compliant_body).
COMPLIANT_BODIES = ("object", "table")
# The impedance controller's torque law implementations (ControllerConfig.torque_backend).
TORQUE_BACKENDS = ("symbolic", "python")
# Drake's names for MultibodyPlantConfig's choices the scene is built with (PhysicsConfig.plant).
CONTACT_MODELS = ("point", "hydroelastic", "hydroelastic_with_fallback")
DISCRETE_CONTACT_APPROXIMATIONS = ("tamsi", "sap", "similar", "lagged")
CONTACT_SURFACE_REPRESENTATIONS = ("triangle", "polygon")
# How a primitive run's agent chooses (PrimitiveTrainConfig.chooser): its critic's scores, the
# reward predicted by its outcome model (rl/primitive/outcome/chooser.py; the run's
# outcome_model.pt), or the value learned from the 6D expert's labels (rl/primitive/value_chooser/chooser.py;
# the run's chooser_value.pt).
PRIMITIVE_CHOOSERS = ("critic", "outcome_model", "expert_value")
# What an outcome model reads of each candidate (rl/primitive/outcome/model.INPUT_KINDS, the
# same names): its own numbers, or object-relative ones (`corn-drake fit-outcome --inputs`).
OUTCOME_INPUT_KINDS = ("raw", "box_contact")
# Where the 6D expert's candidate primitives come from (config/planner.PlannerConfig.sources;
# rl/planner/sources.SOURCES registers one function per name): a learned primitive run's own
# candidates, or an analytic kind (rl/planner/kinds.py).
PLANNER_SOURCES = ("policy", "push", "turn", "topple")
