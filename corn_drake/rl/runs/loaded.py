"""A run of any kind, loaded once for whoever acts with it: `evaluate` runs its episodes, `ship`
packs its weights (evaluation/shipping.py), `gallery` paints it, `label` and `demo` act with it.

LoadedRun is what every kind of `--run` holds once loaded: the run's own config, its agent in
eval mode, which checkpoint file and how many env steps its weights hold (what a report records,
and what `ship` checks a report against), and `configure`, which applies `--task` / `--set` the
way that kind of run takes them. The kinds themselves (a PPO teacher, a DAgger student, a
contact-primitive policy, a reference controller, the 6D expert) are its subclasses, declared in
one registry (rl/runs/kinds.py), whose `load_any_run` tells them apart. The commands only parse
flags and print.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar


@dataclass
class LoadedRun:
    """A loaded run: `run` (as given), `config` (its own: TrainConfig, DistillConfig or
    PrimitiveTrainConfig; None for a reference or the planner until `configure`), `agent` (eval
    mode; a reference's and the planner's are made by `configure`), `policy` (the report's name
    for it), and for a run folder `env_steps` and `checkpoint_file` (of the weights loaded:
    prev.pt after a fallback) and `weights_folder` (whose checkpoints/ holds that file: a
    shipped outcome folder's sibling, for one that names agent_weights).

    What a kind declares (class attributes, set by each kind in rl/runs/kinds.py):
    NAME, its name in reports and folders; WHAT, how help and errors describe it (DETAIL: what
    help adds); NAMES, the
    names `--run` takes for it instead of a folder; CHECKPOINTS, whether `--checkpoint` picks
    one of its kept checkpoints; FLAGS, evaluate's per-kind flags it takes (their dests);
    RECORDS, whether evaluate can record its episodes to Meshcat; RUNNER, the episode runner
    that plays it ("diagram": evaluation/episodes.py, "planner": evaluation/planner_episodes.py);
    PAINTS, what `gallery` paints on its cloud (None: nothing); PACK, how `ship` packs its
    weights (None: it has none); PERCEIVES, whether it sees through the cameras (its report and
    card name the perception chain); HINTS, what a refusal of a flag it does not take adds."""

    NAME: ClassVar[str] = ""
    WHAT: ClassVar[str] = ""
    DETAIL: ClassVar[str] = ""
    NAMES: ClassVar[tuple[str, ...]] = ()
    CHECKPOINTS: ClassVar[bool] = False
    FLAGS: ClassVar[frozenset] = frozenset()
    RECORDS: ClassVar[bool] = True
    RUNNER: ClassVar[str] = "diagram"
    PAINTS: ClassVar[str | None] = None
    PACK: ClassVar[str | None] = None
    PERCEIVES: ClassVar[bool] = False
    HINTS: ClassVar[dict[str, str]] = {}

    run: str
    config: Any
    agent: Any
    policy: str
    env_steps: int | None = None
    checkpoint_file: str | None = None
    weights_folder: Path | None = None

    @property
    def kind(self) -> str:
        """The kind's name (NAME), as reports and run folders spell it."""
        return self.NAME

    @classmethod
    def load(cls, run: str, checkpoint: str = "") -> "LoadedRun":
        raise NotImplementedError

    @property
    def checkpoint_path(self) -> Path:
        """The very file the weights were loaded from."""
        return self.weights_folder / "checkpoints" / self.checkpoint_file

    def weights_hash(self) -> str | None:
        """sha256 over what decides this run's choices: its config.yaml, the checkpoint file its
        weights were loaded from and the chooser's model files beside them (None for a kind
        without weights). A report records it; `ship` packs only the weights whose hash the
        report it quotes recorded."""
        if self.PACK is None:
            return None
        # Imported here: the registry of kinds is read while the CLI's parser is built, which
        # must not import Drake (tests/test_cli_startup.py).
        from corn_drake.rl.checkpoints import weights_hash

        return weights_hash(Path(self.run), self.checkpoint_path)

    def report_fields(self) -> dict:
        """What a report of this run records of the weights it measured: `ship` compares
        env_steps and checkpoint with the weights it packs."""
        return {"env_steps": self.env_steps, "checkpoint": self.checkpoint_file,
                "weights_sha256": self.weights_hash()}

    def card_run(self) -> str | None:
        """The shipped folder whose card says which object library this run's numbers were
        measured on (evaluate warns when given another): the run itself by default."""
        return self.run

    def configure(self, task: str | None, sets: list[str]):
        """(the TrainConfig-like config the episodes run, the overrides it makes of the run's
        own: config.overrides.config_changes rows) for `--task` (None: the run's own task) and
        `--set` items, as this kind takes them."""
        raise NotImplementedError

    def evaluated_env(self, env, perception: str | None):
        """(the env config the episodes run in, the report fields it adds) for the configured
        `env`: the env itself for a kind that sees no cameras."""
        return env, {}
