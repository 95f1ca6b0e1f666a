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
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

from corn_drake.config.plumbing.loader import load_config
from corn_drake.config.plumbing.overrides import config_changes, set_fields
from corn_drake.config.plumbing.yaml_io import config_fields
from corn_drake.errors import InputError
from corn_drake.run_folders.config_file import run_config_path, write_run_config
from corn_drake.run_folders.guards import LOCK_NAME, lock_folder, refuse_config_changes


def _other_folder(out: Path) -> list[str]:
    """What `out` holds besides a lock, when it is a folder with no run config; else []."""
    if not out.is_dir() or run_config_path(out).is_file():
        return []
    return sorted(name for name in os.listdir(out) if name != LOCK_NAME)


def refuse_other_folder(out: Path) -> None:
    """InputError when `out` is a folder that holds something but no run (no config.yaml): an
    object library, a folder of notes. Taking it over would add config.yaml, checkpoints/ and
    tb/ to it and overwrite its lock file. Checked before the lock is taken, so nothing of it
    changes. An empty folder, or one holding only a lock a killed new run left, is fine."""
    found = _other_folder(out)
    if found:
        shown = ", ".join(found[:5]) + (f" and {len(found) - 5} more" if len(found) > 5 else "")
        raise InputError(f"--out {out} is not a run folder (no {run_config_path(out).name}) and "
                         f"not empty: it holds {shown}; give a new or empty folder")


def _refusal(cfg) -> str | None:
    """The one line today's checks (`cfg.check()`, where the schema has one) give `cfg`, or
    None when they accept it."""
    check = getattr(cfg, "check", None)
    if check is None:
        return None
    try:
        check()
    except InputError as e:
        return str(e)
    return None


def fields_refused_as_recorded(recorded, requested) -> set[str]:
    """The dotted fields whose recorded value today's checks refuse and `requested` corrects.

    A folder can hold a config that today's checks refuse (recorded by an older version, or
    before a check existed). Holding the user to it would refuse the corrected command forever
    ("recorded nan, requested 0.5"): a poisoned folder. Each round finds the field whose
    requested value changes the refusal, takes it, and checks again, until the recorded config
    with the taken fields is accepted or no requested value helps."""
    refusal = _refusal(recorded)
    if refusal is None:
        return set()
    differing = [c.key for c in config_changes(recorded, requested)]
    taken: set[str] = set()
    current = recorded
    while refusal is not None:
        for key in differing:
            if key in taken:
                continue
            trial = set_fields(current, {key: config_fields(requested).get(key)}, "resume")
            trial_refusal = _refusal(trial)
            if trial_refusal != refusal:
                taken.add(key)
                current, refusal = trial, trial_refusal
                break
        else:
            break
    return taken


# Which kind of run each schema's command writes (run_folders.config_file.run_kind's names), what
# to call each kind, and the command that resumes it.
KIND_OF_SCHEMA = {"TrainConfig": "train", "PrimitiveTrainConfig": "primitive",
                  "DistillConfig": "distill"}
KIND_WORDS = {"train": "a dense PPO teacher run", "primitive": "a contact-primitive run",
              "distill": "a DAgger student run"}
RESUMED_BY = {"train": "corn-drake train --policy POLICY --out OUT",
              "primitive": "corn-drake train --policy primitive --out OUT",
              "distill": "corn-drake distill --out OUT"}


def refuse_other_kind(out: Path, schema: type) -> None:
    """An InputError naming what `out` holds and the command that resumes it, when it holds a
    run of another kind than `schema`'s command writes (instead of a config error listing
    unknown fields)."""
    from corn_drake.run_folders.config_file import run_kind

    wanted = KIND_OF_SCHEMA.get(schema.__name__)
    if wanted is None:
        return
    try:
        held = run_kind(str(out))
    except InputError:
        return  # not a run config of any kind: load_config names what is wrong with it
    if held != wanted:
        raise InputError(f"--out {out} holds {KIND_WORDS[held]} (`{RESUMED_BY[held]}` resumes "
                         f"it), not {KIND_WORDS[wanted]}: give another --out".replace(
                             "OUT", str(out)))


@dataclasses.dataclass
class ResumableRun:
    out: Path
    recorded: Any  # the config the run recorded (None: a new run)

    @classmethod
    @contextmanager
    def open(cls, out: str | Path, schema: type, resume_required: bool = False,
             check_new: Callable[[], Any] | None = None) -> Iterator["ResumableRun"]:
        """Locks `out` and reads the config it records, if any, as `schema`. With
        `resume_required`, a folder that holds no run is refused (a mistyped --out). A folder
        that holds something else is refused before it is locked; `check_new()` (the new run's
        own argument checks) runs first, so a mistyped argument is named before the folder."""
        out = Path(out)
        path = run_config_path(out)
        if resume_required and not path.is_file():
            raise InputError(f"--resume: {out} holds no run to resume (no {path.name}); "
                             "leave --resume off to start one")
        if _other_folder(out):
            if check_new is not None:
                check_new()
            refuse_other_folder(out)
        if path.is_file():
            refuse_other_kind(out, schema)
        with lock_folder(out):
            yield cls(out, load_config(schema, path) if path.is_file() else None)

    @property
    def is_new(self) -> bool:
        return self.recorded is None

    def refuse_changes(self, cfg, *, may_grow: Iterable[str], may_change: Iterable[str],
                       name: Callable[[str], str]) -> None:
        """On a resume, an InputError listing every field of `cfg` that differs from the
        recorded config other than those that may grow or change, each named by `name` (the
        argument behind a field)."""
        if self.recorded is not None:
            corrected = fields_refused_as_recorded(self.recorded, cfg)
            refuse_config_changes(self.out, self.recorded, cfg, may_grow=may_grow,
                                  ignore=set(may_change) | corrected, name=name)

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
