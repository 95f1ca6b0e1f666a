"""PrimitiveAgent: the contact-primitive policy — the frozen CORN encoder's per-location features,
a per-location actor (the push motion at each location) and a twin per-location critic.

The policy's choice for an observation: the location with the highest score, the score being
the critic's Q1 at that location with the actor's motion there (HACMan's per-point critic), and
that motion; or, for a run whose config's `chooser` is "outcome_model", the candidate of highest
reward predicted by its outcome model (rl/primitive/outcome/chooser.py). `choose` returns the chosen
location's index into the cloud (the env action's `point`), the motion, the location's own index
and the scores of every location (for display).

Checkpoint (`agent` entry of a primitive run's checkpoint, state_dict()): the actor's and the
critic's weights and the network shape; the encoder is the run's encoder.pt, as for the dense
policies (rl/checkpoints.run_encoder_path).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from corn_drake.contract import PRIMITIVE_LOCAL_DIM as LOCAL_DIM
from corn_drake.nn.primitive_features import global_dim, location_features
from corn_drake.nn.primitive_heads import PrimitiveActor, PrimitiveCritic

AGENT_KIND = "primitive"
OBS_KEYS_USED = ("cloud", "hand_state", "goal", "normals", "object_position")


def obs_to_torch(obs: dict[str, np.ndarray]) -> tuple[bool, dict[str, torch.Tensor]]:
    """(whether `obs` was one unbatched observation, its keys the features use as float32
    tensors with a batch axis)."""
    single = np.asarray(obs["cloud"]).ndim == 2
    out = {}
    for key in OBS_KEYS_USED:
        value = torch.as_tensor(np.asarray(obs[key]), dtype=torch.float32)
        out[key] = value.unsqueeze(0) if single else value
    return single, out


class PrimitiveAgent(nn.Module):
    kind = AGENT_KIND
    has_attention = False  # the dense policies' patch attention; this one shows its scores

    def __init__(self, encoder, hidden: int = 256, primitive_config=None):
        """`primitive_config`: how the executor runs the primitives (PrimitiveConfig; the
        default one when None): which locations it would give up decides the mask."""
        super().__init__()
        from corn_drake.config.primitive import PrimitiveConfig

        self.primitive_config = primitive_config or PrimitiveConfig()
        if getattr(encoder, "kind", None) not in ("corn", "p2v-lite", "rot"):
            raise ValueError(f"the primitive policy needs a patch encoder (corn), got "
                             f"{getattr(encoder, 'kind', type(encoder).__name__)!r}")
        self.encoder = encoder
        for p in self.encoder.parameters():
            p.requires_grad_(False)
        self.hidden = hidden
        dim = encoder.network.dim
        self.actor = PrimitiveActor(dim, LOCAL_DIM, global_dim(dim), hidden)
        self.critic = PrimitiveCritic(dim, LOCAL_DIM, global_dim(dim), hidden)
        # Set by load_primitive_run for a run that chooses by its outcome model
        # (rl/primitive/outcome/chooser.OutcomeChooser), with the task whose reward it predicts (evaluate
        # replaces it with the evaluated task's).
        self.outcome_chooser = None
        self.task = None
        self.checkpoint_file = None  # the file the weights came from (evaluate's report)

    @torch.no_grad()
    def features(self, obs: dict[str, np.ndarray]) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
        """(features, candidates) of a batch of observations (numpy, batched). The features'
        "mask" (B, L) marks the locations the executor would not give up at once: a point whose
        pre-contact point lies below the table (the object's underside,
        PrimitivePlanner._start). The policy never chooses the others, so greedy evaluation
        cannot repeat a primitive that does nothing episode-long."""
        _, batch = obs_to_torch(obs)
        self.encoder.eval()
        features, candidates = location_features(self.encoder, batch)
        features["mask"] = self._reachable(batch, candidates)
        return features, candidates

    def _reachable(self, batch: dict[str, torch.Tensor], candidates: torch.Tensor) -> torch.Tensor:
        from corn_drake.nn.encoders.patchify import gather_points
        from corn_drake.systems.control.primitive_executor import reachable_from_above

        z = gather_points(batch["cloud"], candidates)[..., 2]
        nz = gather_points(batch["normals"], candidates)[..., 2]  # unit normals
        return reachable_from_above(z, nz, self.primitive_config).float()

    def scores_and_motions(self, features: dict[str, torch.Tensor]
                           ) -> tuple[torch.Tensor, torch.Tensor]:
        """(per-location scores, -inf where features["mask"] rules a location out; the actor's
        motions): rl/primitive/td3.scores_and_motions with this agent's networks."""
        from corn_drake.rl.primitive.td3 import scores_and_motions

        return scores_and_motions(self.actor, self.critic, features)

    def choose(self, obs: dict[str, np.ndarray]) -> dict:
        """The greedy choice for one observation: {"point" (cloud index), "motion" (3,),
        "location" (index among the candidates), "scores" (L,), "usable" (L,), "candidates"
        (L,), "motions" (L, 3: the actor's motion at every location)}."""
        single, _ = obs_to_torch(obs)
        if not single:
            raise ValueError("PrimitiveAgent.choose takes one observation (cloud (N, 3))")
        if self.outcome_chooser is not None:
            return self.outcome_chooser.choose(self, obs, self.task)
        features, candidates = self.features(obs)
        scores, motions = self.scores_and_motions(features)
        location = int(torch.argmax(scores[0]))
        shown = scores[0].numpy().astype(np.float64)
        finite = np.isfinite(shown)
        # Ruled-out locations show as the lowest score (displays colour by score).
        shown[~finite] = shown[finite].min() if finite.any() else 0.0
        return {"point": int(candidates[0, location]),
                "motion": motions[0, location].numpy().astype(np.float64),
                "location": location, "scores": shown,
                "usable": features["mask"][0].numpy() > 0.5,
                "candidates": candidates[0].numpy(),
                "motions": motions[0].numpy().astype(np.float64)}

    def location_count(self) -> int:
        """How many candidate locations (patch centres) the agent scores per observation."""
        return self.encoder.network.num_patches

    def network_state(self) -> dict:
        return {"hidden": self.hidden,
                "actor": self.actor.state_dict(), "critic": self.critic.state_dict()}

    def load_network_state(self, state: dict, source) -> None:
        """The actor's and critic's weights from network_state()."""
        from corn_drake.errors import InputError

        # Checkpoints written before issue 52 name their locations; cloud points are retired.
        if state.get("locations", "patch") != "patch":
            raise InputError(f"{source}: a primitive agent of {state['locations']!r} locations, "
                             f"which were retired (config/retired.py); only patch centres load")
        if state.get("hidden") != self.hidden:
            raise InputError(f"{source}: a primitive agent with hidden {state.get('hidden')}, "
                             f"not hidden {self.hidden}")
        self.actor.load_state_dict(state["actor"])
        self.critic.load_state_dict(state["critic"])


def agent_for(cfg, encoder) -> PrimitiveAgent:
    """The agent a PrimitiveTrainConfig describes (untrained heads) around `encoder`."""
    return PrimitiveAgent(encoder, cfg.hidden, cfg.primitive)


def load_primitive_run(run_dir, checkpoint: str = ""):
    """(PrimitiveTrainConfig, PrimitiveAgent in eval mode carrying `primitive_config`, the
    primitives it was trained for) of a `train --policy primitive` run folder, from its
    config.yaml, encoder.pt and checkpoints/last.pt (prev.pt if need be; its agent_weights
    folder's when the config names one) or, given `checkpoint`, that file of its checkpoints
    folder; with chooser "outcome_model", its
    outcome_model.pt too (the agent then chooses by it, for the config's task)."""
    from pathlib import Path

    from corn_drake.config.plumbing.loader import load_config
    from corn_drake.config.primitive import PrimitiveTrainConfig
    from corn_drake.config.choices import PRIMITIVE_CHOOSERS
    from corn_drake.errors import InputError, MissingInputError
    from corn_drake.rl.checkpoints import agent_weights_folder, run_encoder_path
    from corn_drake.rl.pretrained_encoders import load_encoder
    from corn_drake.run_folders.config_file import run_config_path
    from corn_drake.storage.checkpoint_files import load_checkpoint_and_file

    run_dir = Path(run_dir)
    cfg = load_config(PrimitiveTrainConfig, run_config_path(run_dir))
    # A shipped outcome-model folder reads a sibling folder's actor and critic (agent_weights).
    ckpt = agent_weights_folder(run_dir, cfg.agent_weights) / "checkpoints" / (
        checkpoint or "last.pt")
    loaded = load_checkpoint_and_file(ckpt, required=("agent", "global_step"),
                                      fallback=not checkpoint)
    if loaded is None:
        raise MissingInputError(f"no checkpoint in {run_dir}: expected {ckpt}")
    state, used = loaded
    if cfg.chooser == "critic":  # a chooser's folder carries its proposing run's checkpoint
        from corn_drake.rl.checkpoints import check_env_hash

        check_env_hash(state, cfg, run_dir, used)
    encoder = load_encoder("corn", run_encoder_path(run_dir, cfg.encoder), cfg.allow_weak_encoder)
    agent = agent_for(cfg, encoder)
    agent.load_network_state(state["agent"], used)
    agent.eval()
    agent.checkpoint_file = used.name
    if cfg.chooser not in PRIMITIVE_CHOOSERS:
        raise InputError(f"{run_config_path(run_dir)}: chooser must be one of "
                         f"{', '.join(PRIMITIVE_CHOOSERS)}, got {cfg.chooser!r}")
    if cfg.chooser in ("outcome_model", "expert_value"):
        from corn_drake.rl.primitive.outcome.chooser import OutcomeChooser
        from corn_drake.rl.primitive.outcome.model_file import load_outcome_parts
        from corn_drake.rl.primitive.outcome.model import MODEL_FILE

        parts = load_outcome_parts(run_dir / MODEL_FILE)
        agent.outcome_chooser = OutcomeChooser(parts.model, parts.facts["tokens"], parts.facts)
        agent.task = cfg.env.task
    if cfg.chooser == "expert_value":
        # The learned 6D chooser (rl/imitation/): its value network picks among the candidates
        # the outcome model's choices propose.
        from corn_drake.rl.primitive.value_chooser.chooser import ValueChooser
        from corn_drake.rl.primitive.value_chooser.value_model import (MODEL_FILE as VALUE_FILE,
                                                                       load_value_model)

        model, facts = load_value_model(run_dir / VALUE_FILE)
        agent.outcome_chooser = ValueChooser(model, facts, agent.outcome_chooser)
    return cfg, agent, int(state["global_step"])
