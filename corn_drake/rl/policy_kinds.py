"""The teacher policy variants (the paper's comparison) and the encoder each one takes.

One home for the names, without torch, so command-line parsers list them cheaply and every
command offers the same ones:
  corn      frozen contact-pretrained patch encoder + cross-attention head
  e2e       the same patch encoder, randomly initialised and trained by PPO
  p2v-lite  frozen patch encoder pretrained with point2vec's self-distillation + cross-attention
  rot       frozen patch encoder pretrained on relative rotations + cross-attention
  pn        frozen contact-pretrained PointNet's global feature + MLP head
  state     no cloud: bounding-box keypoints and hand pose + MLP head
"""

# The names live in config/choices.py, beside the other names a config field is checked against.
from corn_drake.config.choices import POLICY_KINDS, PRIMITIVE_POLICY

# The encoder.pt kind (nn/encoder_io.ENCODER_KINDS) a policy needs: the kind names the network
# and how it was pretrained, so `--policy corn` refuses a P2V-lite encoder and the reverse.
ENCODER_KIND = {"corn": "corn", "e2e": "corn", "pn": "pointnet", "p2v-lite": "p2v-lite",
                "rot": "rot"}

# Policies whose encoder PPO never trains: its features can be computed once per collected
# batch and reused in every PPO epoch (rl/training/ppo_trainer.py).
FROZEN_ENCODER_POLICIES = ("corn", "pn", "p2v-lite", "rot")

# Policies that cross-attend over the patch encoder's tokens (the rest use an MLP head).
TOKEN_POLICIES = ("corn", "e2e", "p2v-lite", "rot")

# The contact-primitive policy (rl/primitive/agent.py): the frozen CORN encoder's patch tokens
# choose where to push; trained off-policy by `train --policy primitive`
# (rl/training/primitive_trainer.py), not a PPO variant, so it is not in POLICY_KINDS (the dense comparison's list).
TRAIN_POLICIES = (*POLICY_KINDS, PRIMITIVE_POLICY)
