"""Packing a trained run into a self-contained weights folder with its card (`corn-drake ship`,
whose module docstring says what the folder holds), and the checks that keep a card from
quoting a number its weights did not earn.

A card quotes an `evaluate` report. The report must be of this run or of the shipped folder
(its `run`), on unseen objects, without overrides, of the weights shipped: the report records
the checkpoint file and env steps it measured (rl/runs/loaded.LoadedRun.report_fields), and
both must be those of the weights packed, so a report measured at 3,200 steps cannot be paired
with 3,520-step weights. A partial report (`complete: false`, an interrupted evaluate) is
refused unless asked for, and then the card says `complete: false`.

Older reports: one without `complete` is whole (evaluate wrote nothing on an interrupt before
the key existed); one without `checkpoint` measured last.pt (the only file evaluate read
then); one without `env_steps` (students' reports, before evaluate recorded their steps)
cannot be checked and is accepted with a warning naming it, so the shipped cards' reports in
the results pages still ship. Every report evaluate writes now records both.

Lives below the commands so that `ship` only parses flags and prints; the run is loaded as
`evaluate` loads it (rl/runs/kinds.load_any_run), so a run that ships is a run that evaluates.
"""

from __future__ import annotations

import sys
from pathlib import Path

from corn_drake.errors import InputError, MissingInputError


def read_report(path: str, runs: tuple[str, str], allow_partial: bool = False) -> dict:
    """The `evaluate` report at `path`, checked to quote run runs[0] (or its shipped folder
    runs[1]) on its own task and the unseen split (check_report); a partial one only with
    `allow_partial`. Errors name --report."""
    from corn_drake.storage.atomic_files import read_json

    run, out = runs
    if Path(out).resolve() == Path(run).resolve():
        raise InputError(f"--out {out} is the run folder itself")
    report = read_json(path, "--report")
    check_report(report, runs, path)
    check_report_numbers(report, path)
    if report.get("complete", True) is False and not allow_partial:
        raise InputError(f"--report {path} is partial (complete: false, {len(report['episodes'])}"
                         f" of {report.get('episodes_requested', '?')} episodes); a card quotes "
                         "a finished evaluation (--allow-partial ships it, its card saying "
                         "complete: false)")
    return report


def check_report(report: dict, runs: tuple[str, ...], path: str) -> None:
    """A report a card may quote for runs[0] (or the shipped runs[1]): an InputError naming
    --report `path` otherwise."""
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


def check_report_numbers(report: dict, path: str) -> None:
    """The numbers a card quotes are those of the report's own episodes: its success rates
    recomputed from its rows, `complete` from how many of the episodes asked for it holds, each
    episode once. An InputError naming --report `path` and the number otherwise (an edited
    report)."""
    import numpy as np

    episodes = report["episodes"]
    if not episodes:
        raise InputError(f"--report {path}: no episodes to quote")
    rate = float(np.mean([bool(e.get("success")) for e in episodes]))
    if abs(float(report["success_rate"]) - rate) > 1e-9:
        raise InputError(f"--report {path}: its success_rate {report['success_rate']} is not its "
                         f"{len(episodes)} episodes' ({rate:.4f}); the report was edited")
    by_object: dict = {}
    for e in episodes:
        by_object.setdefault(e.get("object"), []).append(bool(e.get("success")))
    balanced = float(np.mean([np.mean(v) for v in by_object.values()]))
    if report.get("balanced_success_rate") is not None and \
            abs(float(report["balanced_success_rate"]) - balanced) > 1e-9:
        raise InputError(f"--report {path}: its balanced_success_rate "
                         f"{report['balanced_success_rate']} is not its episodes' "
                         f"({balanced:.4f}); the report was edited")
    numbers = [e["episode"] for e in episodes if "episode" in e]
    if len(set(numbers)) != len(numbers):
        raise InputError(f"--report {path}: an episode is listed twice; the report was edited")
    requested = report.get("episodes_requested")
    if requested is not None and report.get("complete", True) != (len(episodes) >= requested):
        raise InputError(f"--report {path} says complete: {report.get('complete', True)} with "
                         f"{len(episodes)} of the {requested} episodes asked for; the report "
                         "was edited")


def check_weights_hash(report: dict, path: str, loaded, stream=None) -> None:
    """The report measured these very weights: the weights_sha256 it recorded is that of the
    run it names (rl/runs/loaded.LoadedRun.weights_hash: config, checkpoint, chooser files), or
    an InputError (retrained, even to the same step count, or edited since). A report from
    before the hash was recorded gets a warning."""
    recorded = report.get("weights_sha256")
    if recorded is None:
        print(f"warning: --report {path} records no weights_sha256 (written before evaluate "
              "recorded it): cannot check that it measured these very weights",
              file=stream or sys.stderr)
        return
    if Path(report["run"]).resolve() != Path(loaded.run).resolve():
        from corn_drake.rl.runs.kinds import load_any_run

        loaded = load_any_run(report["run"], references=False)  # the shipped folder it measured
    if loaded.weights_hash() != recorded:
        raise InputError(f"--report {path} measured other weights than {report['run']} holds "
                         "now (its config, checkpoint or chooser changed since: weights_sha256 "
                         "differs); a card quotes the weights it ships: evaluate them again")


def check_report_library(report: dict, path: str, library: str, stream=None) -> None:
    """The report's episodes were played on objects of `library` (what --library-command
    builds): every episode's object is one of its objects, or an InputError naming them; a
    report of another build of it (its manifest's sha256 differs) gets a warning."""
    import hashlib

    from corn_drake.assets.library import list_objects

    held = set(list_objects(library))
    missing = sorted({e.get("object") for e in report["episodes"]} - held)
    if missing:
        raise InputError(f"--report {path} evaluated objects {', '.join(map(str, missing[:3]))} "
                         f"that --library-command's library {library} does not hold; a card "
                         "names the library its report measured")
    recorded = (report.get("library") or {}).get("manifest_sha256")
    manifest = Path(library) / "manifest.json"
    if recorded and recorded != hashlib.sha256(manifest.read_bytes()).hexdigest():
        print(f"warning: --report {path} was measured on another build of {library} (its "
              "manifest differs); the card records this build's object hashes",
              file=stream or sys.stderr)


def check_measured_weights(report: dict, path: str, run: str, env_steps: int,
                           checkpoint_file: str, stream=None) -> None:
    """The report measured the weights that ship: its checkpoint file and env steps are
    `checkpoint_file` and `env_steps`, those of run `run`'s weights; an InputError naming both
    otherwise. A report that records no env steps (older reports, see above) gets a warning on
    `stream` (stderr) instead: nothing in it says which weights it measured."""
    measured_file = report.get("checkpoint", "last.pt")  # before the key: always last.pt
    if "env_steps" not in report:
        print(f"warning: --report {path} records no env_steps (written before evaluate "
              f"recorded them): cannot check that it measured --run {run}'s {checkpoint_file} at "
              f"{env_steps} steps", file=stream or sys.stderr)
        return
    if (report["env_steps"], measured_file) != (env_steps, checkpoint_file):
        raise InputError(f"--report {path} measured {measured_file} at {report['env_steps']} env "
                         f"steps, but --run {run} ships {checkpoint_file} at {env_steps}; a card "
                         "quotes the weights it ships: evaluate them again")


def ship(run: str, out: str | Path, report: dict, report_path: str, library_command: str,
         library: str, library_seed: int, train_command: str = "") -> dict:
    """Packs run `run` into weights folder `out` for the objects of `library` (built by
    `library_command`, its seed `library_seed`) and writes its card.json, quoting `report`
    (read_report's, from `report_path`); the card. Every check comes before `out` is made: a
    refused ship leaves nothing behind."""
    from corn_drake.evaluation.shipped_card import library_card_fields
    from corn_drake.rl.runs.kinds import load_any_run
    from corn_drake.storage.atomic_files import write_json

    out = Path(out)
    loaded = load_any_run(run, references=False)  # the run must load as evaluate loads it
    if loaded.PERCEIVES and "perception" not in report:
        raise InputError(f"--report {report_path} records no perception chain; a student's card "
                         "quotes an evaluation through it")
    check_measured_weights(report, report_path, run, loaded.env_steps, loaded.checkpoint_file)
    check_weights_hash(report, report_path, loaded)
    # Before OUT is made: the library must be on this machine to record what it holds.
    library_fields = library_card_fields(library)
    check_report_library(report, report_path, library)
    # How each kind packs (its PACK, rl/runs/kinds.py).
    pack = {"teacher": _pack_teacher, "student": _pack_student,
            "primitive": _pack_primitive}[loaded.PACK]
    shipped = pack(loaded, out, library)
    episodes = len(report["episodes"])
    card = {**{k: shipped.pop(k) for k in ("policy", "task", "env_steps")},
            "success_rate": report["success_rate"],
            "balanced_success_rate": report.get("balanced_success_rate"),
            "episodes": episodes,
            # Beside the paper's rule (a pose passed through counts): the successes whose
            # episode ended with the object still on its goal, from the report's rows.
            **_at_rest_fields(report),
            # Only a partial report (shipped with --allow-partial) says so: a whole one's card
            # keeps the keys cards have always had.
            **({"complete": False} if report.get("complete", True) is False else {}),
            "split": "unseen", "report": report_path, "library_command": library_command,
            "library_seed": library_seed,
            "evaluate_command": (f"corn-drake evaluate --run {out.as_posix()} --objects "
                                 f"{library} --split unseen --episodes {episodes} "
                                 "--report eval.json"),
            "train_command": train_command, "source_run": str(run),
            "actions": report.get("actions", "mean"), **shipped, **library_fields}
    if loaded.PERCEIVES:
        card["perception"] = report["perception"]
    card["bytes"] = {p.relative_to(out).as_posix(): p.stat().st_size
                     for p in sorted(out.rglob("*")) if p.is_file() and p.name != "card.json"}
    write_json(out / "card.json", card)
    return card


def _at_rest_fields(report: dict) -> dict:
    """{"successes_ending_at_rest", "success_rate_ending_at_rest"} of the report's rows, both
    None for rows that record no end speed (reports from before they did)."""
    from corn_drake.evaluation.failures import successes_ending_still

    episodes = report["episodes"]
    if not any(e.get("end_speed") is not None for e in episodes):
        return {"successes_ending_at_rest": None, "success_rate_ending_at_rest": None}
    still = successes_ending_still(episodes)
    return {"successes_ending_at_rest": still,
            "success_rate_ending_at_rest": still / len(episodes)}


def _weights(loaded, key: str) -> dict:
    """The checkpoint the run's weights were loaded from (not last.pt read again: after a
    fallback that is prev.pt), holding `key` and its global_step."""
    from corn_drake.storage.checkpoint_files import load_checkpoint

    state = load_checkpoint(loaded.checkpoint_path, required=(key, "global_step"), fallback=False)
    if state is None:
        raise MissingInputError(f"--run {loaded.run}: no checkpoint")
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


def _encoder_card(agent, file) -> dict:
    # Its pretraining record (contact F1 or pretext skill), as the encoder file holds it.
    return {"file": file, "kind": agent.encoder.kind,
            "pretraining": getattr(agent.encoder, "pretraining", None)}


def _pack_teacher(loaded, out: Path, library: str) -> dict:
    """Writes a teacher run's config, weights and encoder into `out`; its card fields."""
    from corn_drake.run_folders.config_file import write_run_config

    cfg, agent = loaded.config, loaded.agent
    state = _weights(loaded, "agent")
    _make_folder(out)
    encoder_card = None
    if cfg.encoder:
        _copy_encoder(cfg, out)
        encoder_card = _encoder_card(agent, "encoder.pt")
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


def _pack_primitive(loaded, out: Path, library: str) -> dict:
    """Writes a contact-primitive run's config, actor and critic and encoder into `out`; its
    card fields. Only what `evaluate` loads (rl/primitive/agent.load_primitive_run) travels:
    the replay files and the learner's targets and optimisers are for resuming a run."""
    from corn_drake.rl.checkpoints import run_encoder_path
    from corn_drake.run_folders.config_file import write_run_config
    from corn_drake.storage.atomic_files import atomic_path, write_json

    run_dir, cfg, agent = Path(loaded.run), loaded.config, loaded.agent
    state = _weights(loaded, "agent")
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
    if cfg.chooser in ("outcome_model", "expert_value"):
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
    history = state.get("history", [])
    if agent.outcome_chooser is not None:
        history = agent.outcome_chooser.fit_history
    write_json(out / "training_history.json",
               {"policy": cfg.policy, "task": cfg.env.task.name, "history": history})
    chooser = {"chooser": cfg.chooser}
    if agent.outcome_chooser is not None:
        # The model that chooses travels with the actor that proposes motions.
        import shutil

        from corn_drake.rl.primitive.outcome.model import MODEL_FILE

        # A learned 6D chooser (rl/imitation/) wraps the outcome model: both files travel.
        value_chooser = getattr(agent.outcome_chooser, "inner", None) is not None
        outcome = agent.outcome_chooser.inner if value_chooser else agent.outcome_chooser
        with atomic_path(out / MODEL_FILE) as tmp:
            shutil.copyfile(run_dir / MODEL_FILE, tmp)
        chooser["outcome_model"] = {"file": MODEL_FILE, **outcome.facts}
        if value_chooser:
            from corn_drake.rl.primitive.value_chooser.value_model import MODEL_FILE as VALUE_FILE

            with atomic_path(out / VALUE_FILE) as tmp:
                shutil.copyfile(run_dir / VALUE_FILE, tmp)
            chooser["chooser_value"] = {"file": VALUE_FILE, **agent.outcome_chooser.facts}
    return {**chooser, "policy": cfg.policy, "task": cfg.env.task.name,
            "env_steps": int(state["global_step"]), "env_steps_unit": "primitives",
            "location_count": agent.location_count(),
            "training_history": "training_history.json",
            "encoder": _encoder_card(agent, cfg.encoder)}


def _pack_student(loaded, out: Path, library: str) -> dict:
    """Writes a student run's config and weights into `out`; its card fields. The student's
    weights hold its encoder, so no encoder file travels."""
    from corn_drake.run_folders.config_file import write_run_config

    cfg = loaded.config
    state = _weights(loaded, "student")
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
    from corn_drake.nn.encoders.encoder_files import load_frozen_encoder

    return load_frozen_encoder(encoder).pretraining if encoder and Path(encoder).is_file() else None
