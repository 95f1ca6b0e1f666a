"""The start-or-resume flow of a training run folder, shared by `train` and `distill`.

    with ResumableRun.open(out, TrainConfig, resume_required=args.resume) as run:
        cfg = ...requested config, on top of run.recorded when there is one...
        run.refuse_changes(cfg, may_grow=..., may_change=..., name=...)   # before any write
        trainer = ...                                                    # reads, writes nothing
        run.write_config(cfg, new_run_line)                              # the first write
        trainer.train(...)

The folder is locked for the whole block (a second command into it refuses), and everything
that can refuse comes before the first write, so a refused resume leaves the run as it was.
"""

from __future__ import annotations

import dataclasses
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

from corn_drake.config.loader import load_config
from corn_drake.config.overrides import config_changes
from corn_drake.errors import InputError
from corn_drake.run_folders.config_file import run_config_path, write_run_config
from corn_drake.run_folders.guards import lock_folder, refuse_config_changes


@dataclasses.dataclass
class ResumableRun:
    out: Path
    recorded: Any  # the config the run recorded (None: a new run)

    @classmethod
    @contextmanager
    def open(cls, out: str | Path, schema: type, resume_required: bool = False
             ) -> Iterator["ResumableRun"]:
        """Locks `out` and reads the config it records, if any, as `schema`. With
        `resume_required`, a folder that holds no run is refused (a mistyped --out)."""
        out = Path(out)
        with lock_folder(out):
            path = run_config_path(out)
            recorded = load_config(schema, path) if path.is_file() else None
            if resume_required and recorded is None:
                raise InputError(f"--resume: {out} holds no run to resume (no {path.name}); "
                                 "leave --resume off to start one")
            yield cls(out, recorded)

    @property
    def is_new(self) -> bool:
        return self.recorded is None

    def refuse_changes(self, cfg, *, may_grow: Iterable[str], may_change: Iterable[str],
                       name: Callable[[str], str]) -> None:
        """On a resume, an InputError listing every field of `cfg` that differs from the
        recorded config other than those that may grow or change, each named by `name` (the
        argument behind a field)."""
        if self.recorded is not None:
            refuse_config_changes(self.out, self.recorded, cfg, may_grow=may_grow,
                                  ignore=may_change, name=name)

    def write_config(self, cfg, new_run: str, kind: str = "run", at_step: int | None = None
                     ) -> None:
        """Writes `cfg` as the run's config.yaml and prints what happened: `new_run` for a new
        `kind` of run, else the step it resumes at (when given) and what the accepted
        overrides changed."""
        write_run_config(cfg, self.out)
        if self.recorded is None:
            print(f"new {kind} {self.out}: {new_run}")
        else:
            changes = config_changes(self.recorded, cfg)
            where = f" at step {at_step}" if at_step is not None else ""
            print(f"resume {self.out}{where}: " + ("; ".join(map(str, changes)) or "as recorded"))
