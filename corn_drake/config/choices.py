"""The closed sets of names a config field takes and a command-line flag offers as `choices`.

Kept apart from the configs that check them (student.py, training.py import pydrake): building
the `corn-drake` parser reads these names, and it must import no Drake or torch, so that
`corn-drake --help` and an argument error answer at once (tests/test_cli_startup.py).
"""

CAMERA_MODES = ("fixed", "tracking")
SEGMENTATION_MODES = ("geometric", "ground_truth")
# What the student executes of its own action in DAgger: the Gaussian's mean or a sample of it.
STUDENT_ACTIONS = ("mean", "sample")
# The contact-primitive policy's candidate locations: the encoder's 16 patch centres ("patch"), or
# cloud points ("point": PrimitiveTrainConfig.point_locations of them, farthest-point spread, each
# with its nearest patch's token). Every point of a 512-point cloud is allowed but costs 32x the
# patch policy's replay (~10 KB per transition) and update time: 64 points cost 3.5x the update
# (`bench primitive`, back to back: 98.8 vs 28.6 ms, batch 64; docs/results/primitive/), 128
# points ~6.7x (an ad-hoc timing).
PRIMITIVE_LOCATIONS = ("patch", "point")
# The body points the primitive env's progress reward measures the distance to the goal on
# (PrimitiveConfig.reward_points): the bounding-box corners, or the object's surface cloud.
PRIMITIVE_REWARD_POINTS = ("keypoints", "cloud")
# How a primitive run's agent chooses (PrimitiveTrainConfig.chooser): its critic's scores, or the
# reward predicted by its outcome model (rl/primitive/outcome/chooser.py; the run's outcome_model.pt).
PRIMITIVE_CHOOSERS = ("critic", "outcome_model")
