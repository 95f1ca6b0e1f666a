"""`corn-drake ship`: copy a trained teacher, student or contact-primitive policy into a
self-contained weights folder with its card.

    corn-drake ship --run runs/push_corn --report docs/results/eval_push_corn_unseen.json \
        --library-command "corn-drake objects --num 80 --seed 0 --split unseen --out data/library_unseen" \
        --out models/weights/push_corn

OUT is what `corn-drake evaluate --run OUT` and `distill --teacher OUT` read, and nothing more:

- config.yaml: the run's config, its encoder named relative to OUT (rl/checkpoints.py
  run_encoder_path) and its object library replaced by the library command's --out;
- checkpoints/last.pt: the agent's weights only (no optimiser, RNG or history: a shipped folder
  evaluates and teaches; `train` does not resume it). A student (a `distill` run) ships its
  {"kind": "student", "student": ...} weights, which hold its encoder, and its config keeps the
  teacher it was distilled from as recorded. A contact-primitive run (`train --policy
  primitive`) ships its actor and critic; its replay files (checkpoints/replay_*.npz, hundreds
  of MB, only for resuming) and its TD3 targets and optimisers stay behind; one that chooses by
  an outcome model (config `chooser: outcome_model`) ships its outcome_model.pt too, and its
  card adds `chooser` and the model's facts (`outcome_model`); where a sibling weights folder
  holds its very actor and critic, its config names that folder (`agent_weights`) instead of
  a copy;
- encoder.pt: the frozen encoder the policy reads (corn, pn, p2v-lite, rot), copied;
- card.json: `policy`, `task`, `env_steps`, `success_rate` and `episodes` of `--report` (an
  `evaluate` report of this very run on the unseen split, kept in docs/results/), the
  `library_command` that rebuilds those objects and the `library_seed`, `evaluate_command`,
  `train_command` (as given), `source_run`, and the file sizes. A primitive card adds
  `env_steps_unit: primitives`: its env_steps counts primitives (one decision each, many policy
  periods), not the dense policies' policy periods.

The report must be of this run or of OUT (its `run` field: the same weights), on unseen objects
and without overrides, so a card cannot quote another policy's or another task's number; a
student's card also names the report's perception chain (`perception`).
"""

from __future__ import annotations

import shlex
from pathlib import Path

NAME = "ship"
HELP = ("copy a trained teacher, student or contact-primitive run into a self-contained weights "
        "folder with a JSON card")


def add_arguments(parser):
    parser.add_argument("--run", required=True,
                        help="the `corn-drake train` (teacher, or --policy primitive) or "
                             "`distill` (student) run folder")
    parser.add_argument("--report", required=True,
                        help="`corn-drake evaluate` report of this run on the unseen split")
    parser.add_argument("--library-command", required=True,
                        help="the `corn-drake objects` command that rebuilds the evaluated "
                             "objects (its --out becomes the shipped config's library)")
    parser.add_argument("--train-command", default="",
                        help="the command that trained the run, recorded on the card (default: none)")
    parser.add_argument("--out", required=True, help="weights folder, e.g. models/weights/push_corn")


def library_arguments(command: str) -> dict[str, str]:
    """--num/--seed/--out/--split of a `corn-drake objects` command line; anything else is an
    InputError naming --library-command."""
    from corn_drake.errors import InputError

    words = shlex.split(command)
    if words[:2] != ["corn-drake", "objects"]:
        raise InputError(f"--library-command must be a `corn-drake objects ...` command, got "
                         f"{command!r}")
    values, key = {}, None
    for w in words[2:]:
        if key is not None:
            values[key], key = w, None
        elif w.startswith("--") and "=" in w:
            k, v = w.split("=", 1)
            values[k] = v
        elif w.startswith("--"):
            key = w
    if "--out" not in values:
        raise InputError(f"--library-command {command!r} has no --out")
    return values


def with_hull_budget(command: str, library: dict[str, str]) -> str:
    """`command` (a library command, parsed as `library`) naming its hull budget: the card's
    command must rebuild exactly its objects whatever `objects`' default becomes, so a command
    without --max-hulls gets the one its library was built with (its arguments.json; libraries
    recorded before the flag existed were built with 16). A command naming another budget than
    its library's is an InputError."""
    from corn_drake.commands.objects import UNRECORDED_MAX_HULLS
    from corn_drake.errors import InputError
    from corn_drake.run_folders.guards import read_recorded_arguments

    recorded = (read_recorded_arguments(library["--out"]) or {}).get("--max-hulls",
                                                                      UNRECORDED_MAX_HULLS)
    named = library.get("--max-hulls")
    if named is None:
        return f"{command} --max-hulls {recorded}"
    if str(named) != str(recorded):
        raise InputError(f"--library-command names --max-hulls {named}, but "
                         f"{library['--out']} was built with {recorded}")
    return command


def _check_report(report: dict, runs: tuple[str, ...], path: str) -> None:
    from corn_drake.errors import InputError

    for key in ("success_rate", "episodes", "run", "split", "policy"):
        if key not in report:
            raise InputError(f"--report {path}: no {key!r}; is it a `corn-drake evaluate` report?")
    if Path(report["run"]).resolve() not in {Path(r).resolve() for r in runs}:
        raise InputError(f"--report {path} evaluated run {report['run']!r}, not --run {runs[0]} "
                         f"(or the shipped {runs[1]})")
    if report["split"] != "unseen":
        raise InputError(f"--report {path} is on the {report['split']!r} split; a card quotes "
                         "the unseen objects' success")
    if report.get("overrides"):
        raise InputError(f"--report {path} was run with overrides ({report['overrides']}); a card "
                         "quotes the run on its own task")
    if report.get("checkpoint", "last.pt") != "last.pt":
        raise InputError(f"--report {path} evaluated the kept checkpoint {report['checkpoint']}; "
                         "a card quotes the weights it ships, the run's last.pt")


def run(args) -> int:
    from corn_drake.run_folders.config_file import run_kind
    from corn_drake.errors import InputError
    from corn_drake.storage.atomic_files import read_json, write_json

    run_dir, out = Path(args.run), Path(args.out)
    if out.resolve() == run_dir.resolve():
        raise InputError(f"--out {out} is the run folder itself")
    report = read_json(args.report, "--report")
    _check_report(report, (args.run, args.out), args.report)
    library = library_arguments(args.library_command)
    library_command = with_hull_budget(args.library_command, library)
    kind = run_kind(args.run)
    if kind == "distill" and "perception" not in report:
        raise InputError(f"--report {args.report} records no perception chain; a student's card "
                         "quotes an evaluation through it")
    from corn_drake.evaluation.shipped_card import library_card_fields

    # Before OUT is made: the library must be on this machine to record what it holds (a
    # refused ship leaves nothing behind).
    library_fields = library_card_fields(library["--out"])
    ship = {"distill": _ship_student, "primitive": _ship_primitive}.get(kind, _ship_teacher)
    shipped = ship(run_dir, out, library["--out"])
    card = {**{k: shipped.pop(k) for k in ("policy", "task", "env_steps")},
            "success_rate": report["success_rate"],
            "balanced_success_rate": report.get("balanced_success_rate"),
            "episodes": len(report["episodes"]), "split": "unseen",
            "report": args.report, "library_command": library_command,
            "library_seed": int(library.get("--seed", 0)),
            "evaluate_command": (f"corn-drake evaluate --run {out.as_posix()} --objects "
                                 f"{library['--out']} --split unseen --episodes "
                                 f"{len(report['episodes'])} --report eval.json"),
            "train_command": args.train_command, "source_run": str(args.run),
            "actions": report.get("actions", "mean"), **shipped, **library_fields}
    if kind == "distill":
        card["perception"] = report["perception"]
    card["bytes"] = {p.relative_to(out).as_posix(): p.stat().st_size
                     for p in sorted(out.rglob("*")) if p.is_file() and p.name != "card.json"}
    write_json(out / "card.json", card)
    print(f"shipped {args.run} to {out}: {card['policy']} on {card['task']}, "
          f"{card['env_steps']} {card.get('env_steps_unit', 'steps')}, unseen success "
          f"{card['success_rate']:.3f} over {card['episodes']} episodes; "
          f"{sum(card['bytes'].values()) / 1e6:.1f} MB")
    return 0


def _weights(run_dir: Path, key: str) -> dict:
    from corn_drake.errors import MissingInputError
    from corn_drake.storage.checkpoint_files import load_checkpoint

    state = load_checkpoint(run_dir / "checkpoints" / "last.pt", required=(key, "global_step"))
    if state is None:
        raise MissingInputError(f"--run {run_dir}: no checkpoint")
    return state


def _make_folder(out: Path) -> None:
    """OUT and OUT/checkpoints, made only once the run has loaded: a run that cannot be shipped
    leaves nothing behind."""
    (out / "checkpoints").mkdir(parents=True, exist_ok=True)


def _weights_bytes(state: dict) -> bytes:
    """checkpoints/last.pt's bytes, the same for the same weights: saved through a buffer,
    since torch.save names its archive after the (temporary) file it writes, and a re-shipped
    folder should not add a new copy of unchanged weights to the repository."""
    import io

    import torch

    buffer = io.BytesIO()
    torch.save(state, buffer)
    return buffer.getvalue()


def _save_weights(out: Path, state: dict) -> None:
    """checkpoints/last.pt of `state`, written atomically (_weights_bytes)."""
    from corn_drake.storage.atomic_files import atomic_path

    with atomic_path(out / "checkpoints" / "last.pt") as tmp:
        Path(tmp).write_bytes(_weights_bytes(state))


def _identical_sibling(out: Path, name: str, content: bytes) -> str | None:
    """"../FOLDER" of the first sibling folder of the weights folder `out` whose file `name`
    (relative to that folder) holds exactly `content`; None when none does."""
    for folder in sorted(p for p in out.resolve().parent.iterdir() if p.is_dir()):
        candidate = folder / name
        if folder.name != out.name and candidate.is_file() and \
                candidate.stat().st_size == len(content) and candidate.read_bytes() == content:
            return f"../{folder.name}"
    return None


def _ship_teacher(run_dir: Path, out: Path, library: str) -> dict:
    """Writes a teacher run's config, weights and encoder into `out`; its card fields."""
    from corn_drake.rl.checkpoints import load_run
    from corn_drake.run_folders.config_file import write_run_config

    cfg, agent = load_run(run_dir)  # the run must load as evaluate would load it
    state = _weights(run_dir, "agent")
    _make_folder(out)
    encoder_card = None
    if cfg.encoder:
        _copy_encoder(cfg, out)
        # Its pretraining record (contact F1 or pretext skill), as the encoder file holds it.
        encoder_card = {"file": "encoder.pt", "kind": agent.encoder.kind,
                        "pretraining": getattr(agent.encoder, "pretraining", None)}
    if cfg.env.scene.object.kind == "library":
        cfg.env.scene.object.library = library
    write_run_config(cfg, out)
    _save_weights(out, {"agent": state["agent"], "global_step": state["global_step"]})
    card = {"policy": cfg.policy, "task": cfg.env.task.name,
            "env_steps": int(state["global_step"]), "encoder": encoder_card}
    if cfg.init_from:  # a curriculum run: env_steps counts only its own, not its source's
        card["init_from"] = cfg.init_from
    return card


def _copy_encoder(cfg, out: Path) -> None:
    """OUT/encoder.pt, a copy of the encoder file `cfg` names (resolved as the run reads it);
    `cfg.encoder` then names it relative to OUT."""
    import shutil

    from corn_drake.storage.atomic_files import atomic_path

    with atomic_path(out / "encoder.pt") as tmp:
        shutil.copyfile(cfg.encoder, tmp)
    cfg.encoder = "encoder.pt"


def _ship_primitive(run_dir: Path, out: Path, library: str) -> dict:
    """Writes a contact-primitive run's config, actor and critic and encoder into `out`; its
    card fields. Only what `evaluate` loads (rl/primitive_agent.load_primitive_run) travels:
    the replay files and the learner's targets and optimisers are for resuming a run."""
    from corn_drake.rl.checkpoints import agent_weights_folder, run_encoder_path
    from corn_drake.rl.primitive.agent import load_primitive_run
    from corn_drake.run_folders.config_file import write_run_config

    cfg, agent, _ = load_primitive_run(run_dir)  # the run must load as evaluate would load it
    state = _weights(agent_weights_folder(run_dir, cfg.agent_weights), "agent")
    _make_folder(out)
    # A run's config names its own copy, encoder.pt, relative to the run folder.
    cfg.encoder = run_encoder_path(run_dir, cfg.encoder)
    shared = _identical_sibling(out, "encoder.pt", Path(cfg.encoder).read_bytes())
    if shared is None:
        _copy_encoder(cfg, out)
    else:
        # The frozen encoder is byte for byte a sibling weights folder's (the primitive policies
        # read the shipped push_corn encoder): named there, not copied, so models/weights stays
        # within its size budget (tests/test_shipped_weights.py). evaluate resolves it relative
        # to this folder (rl/checkpoints.run_encoder_path).
        cfg.encoder = f"{shared}/encoder.pt"
    if cfg.env.scene.object.kind == "library":
        cfg.env.scene.object.library = library
    weights = {"agent": state["agent"], "global_step": state["global_step"]}
    cfg.agent_weights = ""
    if cfg.chooser == "outcome_model":
        # Its actor and critic are byte for byte those of the shipped folder that proposes its
        # motions: named there, not copied (models/weights' size budget), as the encoder.
        cfg.agent_weights = _identical_sibling(out, "checkpoints/last.pt",
                                               _weights_bytes(weights)) or ""
    write_run_config(cfg, out)
    if cfg.agent_weights:
        stale = out / "checkpoints" / "last.pt"  # a copy a previous ship of OUT left
        stale.unlink(missing_ok=True)
        (out / "checkpoints").rmdir()
    else:
        _save_weights(out, weights)
    # Its learning curve travels too (the checkpoint's history rows): the run folder does not
    # outlive its machine, and the card's number should come with how it was reached. An
    # outcome run's choices were learned by its model's fit, not by TD3 in this folder: its
    # curve is the fit's (rows of "update" and "huber_loss"; empty for files from before).
    from corn_drake.storage.atomic_files import write_json

    history = state.get("history", [])
    if agent.outcome_chooser is not None:
        history = agent.outcome_chooser.fit_history
    write_json(out / "training_history.json",
               {"policy": cfg.policy, "task": cfg.env.task.name,
                "history": history})
    chooser = {"chooser": cfg.chooser}
    if agent.outcome_chooser is not None:
        # The model that chooses travels with the actor that proposes motions.
        import shutil

        from corn_drake.rl.primitive.outcome.model import MODEL_FILE
        from corn_drake.storage.atomic_files import atomic_path

        with atomic_path(out / MODEL_FILE) as tmp:
            shutil.copyfile(run_dir / MODEL_FILE, tmp)
        chooser["outcome_model"] = {"file": MODEL_FILE, **agent.outcome_chooser.facts}
    return {**chooser, "policy": cfg.policy, "task": cfg.env.task.name,
            "env_steps": int(state["global_step"]), "env_steps_unit": "primitives",
            "locations": cfg.locations, "location_count": agent.location_count(
                cfg.env.scene.object.cloud_points),
            "training_history": "training_history.json",
            "encoder": {"file": cfg.encoder, "kind": agent.encoder.kind,
                        "pretraining": getattr(agent.encoder, "pretraining", None)}}


def _ship_student(run_dir: Path, out: Path, library: str) -> dict:
    """Writes a student run's config and weights into `out`; its card fields. The student's
    weights hold its encoder, so no encoder file travels."""
    from corn_drake.rl.checkpoints import load_student_run
    from corn_drake.run_folders.config_file import write_run_config

    cfg, _ = load_student_run(run_dir)  # the run must load as evaluate would load it
    state = _weights(run_dir, "student")
    _make_folder(out)
    obj = cfg.env.teacher.scene.object
    if obj.kind == "library":
        obj.library = library
    write_run_config(cfg, out)
    _save_weights(out, {"kind": "student", "student": state["student"],
                        "global_step": state["global_step"]})
    return {"policy": "student", "task": cfg.env.teacher.task.name,
            "env_steps": int(state["global_step"]), "teacher": cfg.teacher,
            "trained_perception": cfg.env.segmentation.mode,
            "cameras": cfg.env.cameras.mode,
            "encoder": {"file": None, "kind": "corn", "pretrained_from": cfg.encoder,
                        "pretraining": _pretraining_record(cfg.encoder)}}


def _pretraining_record(encoder: str):
    """The contact-pretraining record of the encoder file a student started from (None when that
    file is not on this machine: the student's weights do not carry it)."""
    from corn_drake.nn.encoder_files import load_frozen_encoder

    return load_frozen_encoder(encoder).pretraining if encoder and Path(encoder).is_file() else None
