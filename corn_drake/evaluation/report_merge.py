"""`corn-drake merge-reports`' core: one report (a policy's or the 6D expert's, or one round of
labels) from the rows files of the parts that split runs played (`--episodes-from`), believed
only as far as checked.

Every part must share every setting. Each row must be an episode of its part's requested range
(the rows file's header, episode_rows.claim_range) played on the object and from the seed
that evaluate gives episode k (objects[k mod n], episode_seed(seed, object, k div n)): a row
copied under another episode number, or edited, is refused, naming the part and the episode.
No episode may come twice. What the parts were asked for and did not play is said, and the
merged report is `complete` only when nothing is missing. A part's last line cut short by a
kill is left in its file and said, not counted.
"""

from __future__ import annotations

import json
from pathlib import Path

from corn_drake.errors import InputError
from corn_drake.evaluation.episodes import episode_seed
from corn_drake.evaluation.episode_rows import read_rows, rows_path_of, settings_of
from corn_drake.evaluation.planner_episodes import labels_path_of, read_labels_by_episode
from corn_drake.storage.atomic_files import write_json, write_text


def requested_of(part: Path, rows: list[dict]) -> range:
    """The episodes `part` was asked for: its header's range, or (a file from before headers
    said it) the range its rows span."""
    header = json.loads(part.read_text().splitlines()[0])
    if header.get("requested"):
        return range(*header["requested"])
    episodes = [r["episode"] for r in rows]
    return range(min(episodes), max(episodes) + 1) if episodes else range(0)


def check_row(row: dict, settings: dict, part: Path, requested: range) -> None:
    """An InputError naming `part` and the episode unless `row` is episode k of `requested`
    on evaluate's object and seed for k."""
    k, objects = row.get("episode"), settings["objects"]
    if not isinstance(k, int) or k not in requested:
        raise InputError(f"{part}: a row of episode {k!r}, outside the episodes "
                         f"{requested.start}..{requested.stop - 1} the part was asked for")
    expected = objects[k % len(objects)]
    seed = episode_seed(settings["seed"], expected, k // len(objects))
    if row.get("object") != expected or row.get("seed") != seed:
        raise InputError(f"{part}: episode {k} names object {row.get('object')!r} and seed "
                         f"{row.get('seed')!r}, but episode {k} is {expected!r} from seed "
                         f"{seed}: the row was copied or edited")


def spans(numbers: list[int]) -> str:
    """"3, 5..9, 12" of sorted integers."""
    out, start = [], None
    for i, n in enumerate(numbers):
        if start is None:
            start = n
        if i + 1 == len(numbers) or numbers[i + 1] != n + 1:
            out.append(f"{start}" if start == n else f"{start}..{n}")
            start = None
    return ", ".join(out)


def merge_reports(parts: list[Path], out: Path, notes: list | None = None) -> dict:
    """One report of the episodes the parts (their REPORT.rows.jsonl files) played, written to
    `out` (and its own rows and labels files) atomically; returns the report. `notes` gets what
    a reader should know (episodes missing, a cut line)."""
    notes = [] if notes is None else notes
    settings = settings_of(parts[0])
    rows, seen, requested = [], {}, set()
    for part in parts:
        if settings_of(part) != settings:
            raise InputError(f"{part}: its settings differ from {parts[0]}'s; only parts of one "
                             "evaluation merge")
        part_rows = read_rows(part, settings, repair=False, notes=notes)
        asked = requested_of(part, part_rows)
        requested.update(asked)
        for row in part_rows:
            check_row(row, settings, part, asked)
            if row["episode"] in seen:
                raise InputError(f"episode {row['episode']} is in both {seen[row['episode']]} "
                                 f"and {part}")
            seen[row["episode"]] = part
            rows.append(row)
    rows.sort(key=lambda r: r["episode"])
    missing = sorted(requested - set(seen))
    if missing:
        notes.append(f"{len(missing)} of the {len(requested)} episodes the parts were asked for "
                     f"are missing: {spans(missing)} (the report says complete: false)")
    labels = {}  # the parts' labels join too (parts written before labels existed have none)
    for part in parts:
        labels.update(read_labels_by_episode(labels_path_of(part), settings))
    report = _report(settings, rows, sorted(requested))
    report["parts"] = [str(p) for p in parts]
    first, stop = (min(requested), max(requested) + 1) if requested else (0, 0)
    header = {"settings": settings, "requested": [first, stop]}
    write_text(rows_path_of(out), "".join(f"{json.dumps(r)}\n" for r in [header, *rows]))
    if labels:
        from corn_drake.rl.planner.labels import LABELS_SUFFIX, plain_path_of
        from corn_drake.rl.planner.search import LABEL_COLUMNS
        from corn_drake.storage.gz_lines import write_lines

        kept = [labels[r["episode"]] for r in rows if r["episode"] in labels]
        labels_out = out.with_name(out.stem + LABELS_SUFFIX)
        write_lines(labels_out, [json.dumps(r) for r in
                                 [{"settings": settings, "columns": LABEL_COLUMNS}, *kept]])
        # An earlier merge's plain labels here are this merge's own older output.
        plain_path_of(labels_out).unlink(missing_ok=True)
    write_json(out, report)
    return report


def _report(settings: dict, rows: list[dict], requested: list[int]) -> dict:
    """The report of merged `rows` as the evaluation its settings name writes it: a policy's
    (settings "runner": "diagram", episodes.policy_report) or the 6D expert's (rows files of
    the expert name no runner: planner_episodes.report_of)."""
    if settings.get("runner") == "diagram":
        from corn_drake.evaluation.episodes import policy_report

        report = policy_report(rows, requested, settings)
        # What evaluate records of the run beside the episodes (its weights, overrides, ...).
        report.update({k: v for k, v in settings.items()
                       if k not in ("runner", "objects", "task", "action_step", "perception")})
        return report
    from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
    from corn_drake.evaluation.planner_episodes import report_of

    facts = {k: v for k, v in settings.items() if k not in ("task", "seed", "objects")}
    report = report_of(rows, load_primitive_env_config(settings["task"]).task, requested, facts)
    report.update({"run": "planner", "policy": "planner", "seed": settings["seed"]})
    return report
