"""Does the policy's own critic know better motions than its actor? `corn-drake evaluate` with the
primitive agent choosing, at every location, the best of its actor's motion and the 26 motions of
a 3 x 3 x 3 grid ({-1, 0, 1}^3 but 0) by its critic's Q1: README.md's item 33.

    .venv/bin/python docs/results/primitive/critic_motion_grid.py evaluate \
        --run models/weights/push_turn_primitive --set primitive.success_at_rest=true \
        --objects data/library --split unseen --episodes 200 --record 0 \
        --report docs/results/primitive/eval_push_turn_shipped_at_rest_critic_motion_grid.json

The arguments are `corn-drake`'s;
only the agent's choice changes (PrimitiveAgent.scores_and_motions, replaced in this process).
"""

from __future__ import annotations

import itertools
import sys

import torch

from corn_drake.rl.primitive import agent as primitive_agent
from corn_drake.rl.primitive.td3 import masked

GRID = torch.tensor([d for d in itertools.product((-1.0, 0.0, 1.0), repeat=3) if any(d)])


@torch.no_grad()
def grid_scores_and_motions(self, features):
    """(per-location best Q1 over the actor's motion and GRID, masked; the motions it picked)."""
    actor = self.actor(features)
    B, L, _ = actor.shape
    options = torch.cat([actor[:, :, None], GRID[None, None].expand(B, L, -1, 3)], dim=2)
    qs = torch.stack([self.critic(features, options[:, :, k])[0]
                      for k in range(options.shape[2])], dim=2)
    best = qs.argmax(dim=2)
    motions = torch.gather(options, 2, best[..., None, None].expand(B, L, 1, 3))[:, :, 0]
    return masked(qs.max(dim=2).values, features), motions


if __name__ == "__main__":
    primitive_agent.PrimitiveAgent.scores_and_motions = grid_scores_and_motions
    from corn_drake.cli import main

    sys.exit(main(sys.argv[1:]))
