"""The closed sets of names a config field takes and a command-line flag offers as `choices`.

Kept apart from the configs that check them (student.py, training.py import pydrake): building
the `corn-drake` parser reads these names, and it must import no Drake or torch, so that
`corn-drake --help` and an argument error answer at once (tests/test_cli_startup.py).
"""

CAMERA_MODES = ("fixed", "tracking")
SEGMENTATION_MODES = ("geometric", "ground_truth")
# What the student executes of its own action in DAgger: the Gaussian's mean or a sample of it.
STUDENT_ACTIONS = ("mean", "sample")
# The contact-primitive policy's candidate locations: the encoder's patch centres. (Every cloud
# point, "point", is what nn/primitive_features.py can also build, but its replay would hold
# 512 tokens per state, 32x the patch replay's ~10 KB per transition: not offered until the
# replay stores patch tokens once and gathers them at sampling.)
PRIMITIVE_LOCATIONS = ("patch",)
