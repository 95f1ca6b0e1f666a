"""`corn-drake gallery`: PNG stills of a teacher's episodes with its attention on the object.

    corn-drake gallery --run models/weights/push_corn --objects data/library_unseen \
        --ids mug_001,toy_002,bottle_000 --out docs/gallery
    corn-drake gallery --run models/weights/push_primitive --objects data/library_unseen \
        --ids mug_001 --animate --out docs/gallery/push_primitive

For each object, one episode (mean actions, seed `evaluate`'s episode_seed(--seed, id, 0), so
the episode is the first one `evaluate --seed` runs on that object) is rendered headless by a
Drake camera at its start, middle and end (viz/gallery.py) and saved side by side as
OUT/<id>.png, the cloud coloured viridis by the policy's attention (yellow: the patches its
queries weigh most at that step), the goal a translucent red copy of the object at its goal
pose. OUT/gallery.json lists each episode's outcome and files.

--animate also renders every step of the same episode (or --frames of them, evenly spaced),
--frame-height pixels tall, and saves them as the looping GIF OUT/<id>.gif (its entry's
`animation` and `animation_steps`).

A contact-primitive run (`train --policy primitive`) has no attention: its stills colour the
cloud by the policy's scores over its contact locations (yellow: where it would rather push)
and mark the contact point of the primitive under way in magenta (evaluation/stills.py); its
entries add the episode's `primitives`.
"""

from __future__ import annotations

from pathlib import Path

from corn_drake.arguments.value_types import seed_int

NAME = "gallery"
# An animation frame's height: small enough that a 40-step episode's GIF stays well under 2 MB,
# large enough to tell the object from its goal copy.
ANIMATION_HEIGHT, MIN_FRAME_HEIGHT, MAX_FRAME_HEIGHT = 192, 48, 480
HELP = ("PNG stills (start, middle, end) of a teacher's episodes, coloured by its attention (a "
        "primitive policy's: by its contact-location scores); --animate: a GIF of each episode")


def add_arguments(parser):
    parser.add_argument("--run", required=True,
                        help="a teacher or contact-primitive run, or a shipped weights folder")
    parser.add_argument("--objects", required=True, help="object library folder")
    parser.add_argument("--ids", default="",
                        help="comma-separated object ids (default: the first 3 unseen)")
    parser.add_argument("--seed", type=seed_int, default=1000,
                        help="as evaluate's --seed: each object's first episode of that evaluation")
    parser.add_argument("--set", action="append", default=[], dest="set", metavar="KEY=VALUE",
                        help="as evaluate's --set: the run's env or, for a primitive run, its "
                             "executor (e.g. primitive.success_at_rest=true: the episode goes on "
                             "until the object rests on its goal); default: none")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace what --out holds (default: a new or empty folder, or a "
                             "gallery of the same --run, whose old pictures are replaced)")
    parser.add_argument("--animate", action="store_true",
                        help="also write each episode as a looping GIF, OUT/<id>.gif")
    parser.add_argument("--frames", type=int, default=0,
                        help="with --animate: this many steps, evenly spaced (default: every step)")
    parser.add_argument("--frame-height", type=int, default=ANIMATION_HEIGHT,
                        help=f"with --animate: frame height in pixels, 4:3 (default "
                             f"{ANIMATION_HEIGHT})")


def montage(images) -> "np.ndarray":
    """The stills side by side, separated by a white gap."""
    import numpy as np

    gap = np.full((images[0].shape[0], 8, 3), 255, np.uint8)
    row = [images[0]]
    for image in images[1:]:
        row += [gap, image]
    return np.concatenate(row, axis=1)


def run(args) -> int:
    import dataclasses

    from corn_drake.assets.library import list_objects, load_object_spec
    from corn_drake.errors import InputError
    from corn_drake.evaluation.episodes import episode_seed
    from corn_drake.storage.atomic_files import ensure_writable, write_json
    from corn_drake.rl.runs.kinds import load_any_run
    from corn_drake.evaluation.stills import record_episode, render_frames
    from corn_drake.viz.gallery import animation_picks, pick_steps, save_gif, save_png

    out = Path(args.out)
    given = [flag for flag, value, default in (("--frames", args.frames, 0),
                                                ("--frame-height", args.frame_height,
                                                 ANIMATION_HEIGHT)) if value != default]
    if given and not args.animate:  # a flag that would change nothing is a mistake to name
        raise InputError(f"{given[0]} shapes the animation: give it with --animate")
    if args.animate and (args.frames == 1 or args.frames < 0):
        raise InputError(f"--frames {args.frames}: an animation needs 2 or more (0: every step)")
    if args.animate and not MIN_FRAME_HEIGHT <= args.frame_height <= MAX_FRAME_HEIGHT:
        raise InputError(f"--frame-height {args.frame_height}: must be {MIN_FRAME_HEIGHT} to "
                         f"{MAX_FRAME_HEIGHT} pixels")
    # What the kind paints on the cloud (rl/runs/kinds.py: PAINTS): a teacher its attention, a
    # primitive policy its location scores; a kind that paints nothing is refused.
    loaded = load_any_run(args.run, references=False)
    cfg, agent = loaded.config, loaded.agent
    if loaded.PAINTS is None or (loaded.PAINTS == "attention" and not agent.has_attention):
        raise InputError(f"--run {args.run} holds a {loaded.policy!r} policy ({loaded.WHAT}), "
                         "which has no cross-attention or location scores to paint")
    # --set as evaluate takes it for this kind of run (rl/runs/kinds.py: configure).
    run_cfg, overrides = loaded.configure(None, args.set)
    # Evaluate samples each object's cloud with its --seed as the env seed: the same here.
    env_cfg = dataclasses.replace(run_cfg.env, seed=args.seed)
    known = list_objects(args.objects)
    ids = [i for i in args.ids.split(",") if i] or list_objects(args.objects, "unseen")[:3]
    unknown = [i for i in ids if i not in known]
    if unknown:
        raise InputError(f"--ids {','.join(unknown)}: not in library {args.objects}")
    from corn_drake.storage.output_owners import check_gallery_owner

    earlier = check_gallery_owner(out, str(args.run), args.overwrite)
    ensure_writable(out, "--out")  # after every check: a refused command writes nothing
    entries = []
    for object_id in ids:
        seed = episode_seed(args.seed, object_id, 0)
        spec = load_object_spec(args.objects, object_id)
        episode = record_episode(agent, env_cfg, spec, seed)
        summary = episode.summary
        stills = render_frames(episode, env_cfg.scene, spec,
                               pick_steps("start,middle,end", len(episode.frames)))
        path = save_png(montage([s.image for s in stills]), out / f"{object_id}.png")
        entry = {"object": object_id, "image": path.name, "steps_shown": [s.step for s in stills],
                 "points_painted": [s.painted_points for s in stills], **summary}
        if args.animate:
            height = args.frame_height
            frames = render_frames(episode, env_cfg.scene, spec,
                                   animation_picks(len(episode.frames), args.frames),
                                   width=(height * 4) // 3, height=height)
            gif = save_gif([f.image for f in frames], out / f"{object_id}.gif")
            entry.update(animation=gif.name, animation_steps=[f.step for f in frames])
            print(f"{object_id}: {len(frames)} frames, {gif.stat().st_size / 1e6:.2f} MB; {gif}")
        entries.append(entry)
        print(f"{object_id}: {'success' if summary['success'] else 'no success'} in "
              f"{summary['steps']} steps; {path}")
    painted = loaded.PAINTS
    write_json(out / "gallery.json", {"run": str(args.run), "policy": cfg.policy,
                                      "task": env_cfg.task.name, "objects": args.objects,
                                      "painted": painted, "episodes": entries,
                                      "overrides": [dataclasses.asdict(change)
                                                    for change in overrides]})
    # The earlier gallery's pictures this one did not rewrite (another object, a GIF not asked
    # for now) go: the folder shows one gallery.
    kept = {name for e in entries for name in (e["image"], e.get("animation")) if name}
    for name in set(earlier) - kept:
        (out / Path(name).name).unlink(missing_ok=True)
    return 0
