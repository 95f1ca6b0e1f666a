"""The object library on disk: building it (procedural or from a mesh folder) and reading it.

DIR/manifest.json follows the typed schema of assets/manifest.py (Manifest, LibraryObject,
Rejection). Paths are relative to DIR; every file is written atomically, and a re-run skips
objects already in the manifest (built or rejected). Splits follow assets/splits.py and are
re-assigned over the whole manifest at every save. The wall times of a build go to
DIR/build_timings.json, the one file two builds of the same objects do not share byte for byte
(`objects --workers N` builds the objects in N processes: assets/build_pool.py).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import time
import zlib
from pathlib import Path
from typing import Callable

import numpy as np

from corn_drake.config.plumbing.bounds import check_bounds
from corn_drake.assets.build_pool import in_plan_order
from corn_drake.assets.families import CONVEX_FAMILIES, FAMILIES, UNSEEN_FAMILIES, make_family_mesh
from corn_drake.assets.ingest import SUPPORTED, Rejected, find_mesh_files, load_watertight
from corn_drake.assets.manifest import (LibraryObject, Manifest, Rejection, library_file,
                                        manifest_path, read_manifest, write_manifest)
from corn_drake.assets.processing.process import ProcessConfig, process_object
from corn_drake.errors import InputError, MissingInputError
from corn_drake.assets.splits import INGESTED_FAMILY, MEMBER_FRACTION, assign_splits
from corn_drake.scene.objects import ObjectSpec
from corn_drake.storage.atomic_files import write_json


# Manifest fields load_object_spec reads (ObjectSpec needs all of them to build the scene).
SPEC_FIELDS = ("mass", "unit_inertia", "cloud", "stable_poses", "radius", "bbox_corners", "hulls",
               "visual", "thin")


def list_objects(library: str | Path, split: str | None = None) -> list[str]:
    return read_manifest(library).ids(split)


def empty_split_hint(library: str | Path, split: str, flag: str = "--split") -> str:
    """What to say when `library` has no `split` objects: the splits that have some, as the
    `flag` values that would find them ("" if the library is empty too)."""
    from collections import Counter

    counts = Counter(o.split for o in read_manifest(library).objects)
    held = [f"{n} {name}" for name, n in sorted(counts.items()) if n]
    if not held:
        return ""
    others = " or ".join(f"{flag} {name}" for name, n in sorted(counts.items()) if n)
    return (f" (it holds {', '.join(held)}; an ingested folder of a few meshes has no unseen "
            f"ones): use {flag} all, or {others}")


def object_groups(library: str | Path) -> dict[str, str]:
    """Object id -> its group for per-group reports: the kind of unseen object ("family",
    "member", "ingested"), or the split ("train"; "unseen" in libraries built before groups)."""
    return {o.id: o.unseen_group or o.split for o in read_manifest(library).objects}


def load_object_spec(library: str | Path, object_id: str) -> ObjectSpec:
    library = Path(library)
    obj = read_manifest(library).get(library, object_id)
    obj.require(library, SPEC_FIELDS)

    def array(key):
        return _load_array(library, obj, key)

    spec = ObjectSpec(name=object_id, mass=float(obj.mass),
                      unit_inertia=array("unit_inertia"), com=np.zeros(3),
                      cloud=array("cloud"),
                      stable_poses=array("stable_poses"), radius=float(obj.radius),
                      bbox_corners=array("bbox_corners"),
                      hull_paths=[library_file(library, obj, "hulls", h) for h in obj.hulls],
                      visual_path=library_file(library, obj, "visual", obj.visual),
                      thin=bool(obj.thin))
    _check_spec(spec, f"object {object_id!r} of {manifest_path(library)}")
    return spec


def _check_spec(spec: ObjectSpec, where: str) -> None:
    """InputError naming the object and its manifest for values no simulation can use (a
    hand-edited or damaged library): Drake would fail on them deep inside the plant, naming
    neither, and only when that object's turn came."""
    if not (np.isfinite(spec.mass) and spec.mass > 0):
        raise InputError(f"{where}: mass must be a finite number > 0, got {spec.mass}")
    if not (np.isfinite(spec.radius) and spec.radius > 0):
        raise InputError(f"{where}: radius must be a finite number > 0, got {spec.radius}")
    inertia = np.asarray(spec.unit_inertia, float)
    if inertia.shape != (3, 3) or not np.all(np.isfinite(inertia)) or \
            np.any(np.linalg.eigvalsh((inertia + inertia.T) / 2) <= 0):
        raise InputError(f"{where}: unit_inertia must be a finite positive-definite 3 x 3 matrix")
    poses = np.asarray(spec.stable_poses)
    if poses.ndim != 2 or poses.shape[1] != 7 or len(poses) == 0 or not np.all(np.isfinite(poses)):
        raise InputError(f"{where}: stable_poses must be finite (n >= 1, 7) rows, got shape "
                         f"{poses.shape}")
    if not np.all(np.isfinite(spec.cloud)):
        raise InputError(f"{where}: its cloud holds NaN or infinite values")
    for path in [*spec.hull_paths, spec.visual_path]:
        if not Path(path).is_file() or Path(path).stat().st_size == 0:
            raise MissingInputError(f"{where}: mesh file missing or empty: {path}")
        # Drake makes a convex hull of each (the visual mesh too: scene/builder.py) deep in
        # building the plant, and a file it cannot use ends there in a long traceback naming
        # neither the object nor the library.
        problem = convex_mesh_problem(Path(path))
        if problem:
            raise InputError(f"{where}: mesh file {path} {problem}")


def convex_mesh_problem(path: Path) -> str | None:
    """Why Drake cannot make a solid convex hull of the OBJ file `path` (not OBJ text, fewer
    than 4 vertices, a vertex that is not three finite numbers, all vertices in one plane),
    or None. Reads the vertex lines as Drake's OBJ reader does; faces do not matter to a hull."""
    if path.suffix.lower() != ".obj":
        return "is not an .obj file (a library's meshes are OBJ text)"
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError:
        return "is not OBJ text (binary bytes)"
    except OSError as e:
        return f"cannot be read ({e.strerror or e})"
    vertices = []
    for number, line in enumerate(text.splitlines(), 1):
        parts = line.split()
        if not parts or parts[0] != "v":
            continue
        try:
            xyz = [float(v) for v in parts[1:4]]
        except ValueError:
            xyz = []
        if len(xyz) != 3 or not np.all(np.isfinite(xyz)):
            return f"line {number}: vertex {line.strip()[:60]!r} is not three finite numbers"
        vertices.append(xyz)
    if len(vertices) < 4:
        return (f"has {len(vertices)} vertices: a convex hull needs at least 4 not in one plane"
                + (" (is it an OBJ file?)" if not vertices else ""))
    points = np.asarray(vertices) - np.mean(vertices, axis=0)
    singular = np.linalg.svd(points, compute_uv=False)
    # Exactly flat (or a line, a point) up to rounding: no volume, no contact surface.
    if singular[-1] <= 1e-9 * max(singular[0], 1e-300):
        return f"has all {len(vertices)} vertices in one plane: its convex hull has no volume"
    return None


# The shape each array file of an object must have (None: any length), and what it holds.
ARRAY_SHAPES = {"cloud": ((None, 6), "points and outward normals"),
                "stable_poses": ((None, 7), "poses [p, q_wxyz]"),
                "bbox_corners": ((8, 3), "box corners"), "unit_inertia": ((3, 3), "inertia")}


def _load_array(library: Path, obj: LibraryObject, key: str) -> np.ndarray:
    path = library_file(library, obj, key, getattr(obj, key))
    try:
        array = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise MissingInputError(f"object {obj.id!r} of {manifest_path(library)}: "
                                f"{key} file not found: {path}") from None
    except (OSError, ValueError, EOFError) as e:
        raise InputError(f"object {obj.id!r} of {manifest_path(library)}: cannot read "
                         f"{key} file {path} ({e})") from None
    # A damaged or hand-made file: named here in one line, not deep in the scene's checks.
    shape, what = ARRAY_SHAPES.get(key, (None, ""))
    if shape is not None:
        wanted = "(" + ", ".join("N" if n is None else str(n) for n in shape) + ")"
        if array.ndim != len(shape) or any(n is not None and n != m
                                           for n, m in zip(shape, array.shape)):
            raise InputError(f"{path}: the {key} of object {obj.id!r} must be a {wanted} array of "
                             f"{what}, got shape {array.shape}")
        if not np.issubdtype(array.dtype, np.number) or not np.all(np.isfinite(array)):
            raise InputError(f"{path}: the {key} of object {obj.id!r} holds values that are not "
                             "finite numbers (NaN or infinite)")
    return array


# Wall times measured while building (per object and in all), kept out of manifest.json: they
# differ on every build, and the manifest, like every other file of the library, is the same
# byte for byte for the same seed and objects, whatever the machine's load or --workers.
TIMINGS_NAME = "build_timings.json"


def _load_timings(out: Path) -> dict:
    """The timings recorded so far in `out` (a resume adds to them); a fresh record when there
    is none, or none readable: they are a measurement, not part of the library."""
    try:
        data = json.loads((out / TIMINGS_NAME).read_text())
    except (OSError, ValueError):
        data = None
    if not (isinstance(data, dict) and isinstance(data.get("objects"), dict)
            and isinstance(data.get("build_s"), (int, float))):
        return {"build_s": 0.0, "objects": {}}
    return data


def _save(out: Path, manifest: Manifest, seed: int,
          planned: list[LibraryObject] | None = None, timings: dict | None = None) -> None:
    # The split depends on how many members each family has: re-assign it over the whole manifest
    # so a manifest on disk is always split as a complete build with these objects would be.
    # A build of one split only (`planned`: every object the full build would make) takes each
    # object's split from the planned set instead, where its family's other members are.
    assign_splits(planned if planned is not None else manifest.objects, seed)
    rule = {"seed": seed, "unseen_families": sorted(UNSEEN_FAMILIES),
            "member_fraction": MEMBER_FRACTION}
    if planned is not None:
        by_id = {o.id: o for o in planned}
        extra = [o.id for o in manifest.objects if o.id not in by_id]
        if extra:
            raise InputError(f"{manifest_path(out)} holds objects beyond the {len(planned)} "
                             f"planned ({', '.join(extra[:5])}...): build it with its own "
                             "--num-objects")
        for o in manifest.objects:
            o.split, o.unseen_group = by_id[o.id].split, by_id[o.id].unseen_group
        rule["split_over_planned"] = len(planned)
    manifest.split_rule = rule
    write_manifest(out, manifest)
    if timings is not None:
        write_json(out / TIMINGS_NAME, timings)


def planned_procedural(num: int) -> list[LibraryObject]:
    """The (id, family) of every object a procedural build of `num` makes, in build order: object
    i is member i // F of the i % F-th family (F families, sorted), whatever else is built."""
    families = sorted(FAMILIES)
    return [LibraryObject(id=f"{families[i % len(families)]}_{i // len(families):03d}",
                          family=families[i % len(families)]) for i in range(num)]


def _load_or_new(out: Path) -> Manifest:
    return read_manifest(out) if (out / "manifest.json").is_file() else Manifest()


def _no_pose_reason(fields: dict) -> str:
    held = fields["drops"]["verified"]
    if held:
        return (f"no stable pose found: none of the {held} holding in the training contact "
                "setting holds in the second one")
    return "no stable pose found"


def _add(out: Path, manifest: Manifest, timings: dict, entry: LibraryObject, rng, mesh, convex,
         cfg, cache) -> None:
    """Processes `entry`'s mesh; appends the object, or its rejection, to `manifest`, and its
    step times to `timings`."""
    _append(manifest, timings, _processed(out, entry, rng, mesh, convex, cfg, cache))


def _append(manifest: Manifest, timings: dict, built: tuple[LibraryObject | Rejection, dict]
            ) -> None:
    """Adds one built object (or its rejection) to `manifest` and its step times to `timings`,
    in the order the caller hands them over (plan order: build_procedural)."""
    result, steps = built
    (manifest.rejected if isinstance(result, Rejection) else manifest.objects).append(result)
    if steps:
        timings["objects"][result.id] = steps


def _processed(out: Path, entry: LibraryObject, rng, mesh, convex, cfg,
               cache) -> tuple[LibraryObject | Rejection, dict]:
    """(`entry` with its processed mesh's fields (its files written under `out`), or its
    rejection; the processing's step times, {} for a rejection)."""
    try:
        fields = process_object(mesh, entry.id, out, rng, cfg, convex, cache)
    except Rejected as e:
        return Rejection(entry.source, str(e)), {}
    steps = fields.pop("timings")
    if fields["num_stable_poses"] == 0:
        return Rejection(entry.source, _no_pose_reason(fields)), {}
    # Warnings from loading the file (ingest) come first, then those from processing it.
    warnings = entry.warnings + fields["warnings"]
    return dataclasses.replace(entry, **{**fields, "warnings": warnings}), steps


def _procedural_seed(seed: int, object_id: str) -> int:
    """The seed of one procedural object's mesh and processing: a function of the library's
    seed and the object's id only, so any process builds it the same (objects --workers)."""
    return zlib.crc32(f"{seed}:{object_id}".encode())


def _procedural_source(seed: int, planned: LibraryObject) -> str:
    """The `source` a procedural object (or its rejection) is recorded with."""
    return f"procedural:{planned.family}:{_procedural_seed(seed, planned.id)}"


def _build_planned(out: Path, seed: int, cfg: ProcessConfig,
                   entry_plan: LibraryObject) -> tuple[LibraryObject | Rejection, dict]:
    """One planned procedural object built into `out`: (its manifest entry or its rejection, its
    step times). It depends on (seed, its id) only, so any process may build it."""
    object_id, family = entry_plan.id, entry_plan.family
    obj_seed = _procedural_seed(seed, object_id)
    rng = np.random.default_rng(obj_seed)
    entry = LibraryObject(id=object_id, source=_procedural_source(seed, entry_plan), family=family)
    try:
        mesh = make_family_mesh(family, obj_seed)
    except ValueError as e:
        return Rejection(entry.source, str(e)), {}
    return _processed(out, entry, rng, mesh, family in CONVEX_FAMILIES, cfg, out / ".coacd_cache")


def objects_to_build(planned: list[LibraryObject], manifest: Manifest, seed: int,
                     wanted: set[str] | None = None) -> list[LibraryObject]:
    """The planned objects a (resumed) build still has to make, in plan order: those neither in
    the manifest nor rejected, and only those in `wanted` when given (--split). A rejection
    names its object's source, not its id, so both are checked: a rejected object is decided,
    and building it again would only add the same rejection twice. The progress bar's total is
    this list's length, so its rate and ETA count only the work left."""
    built = {o.id for o in manifest.objects}
    rejected = {r.source for r in manifest.rejected}
    return [o for o in planned
            if o.id not in built and _procedural_source(seed, o) not in rejected
            and (wanted is None or o.id in wanted)]


def _clear_stale_temporaries(out: Path, todo: list[LibraryObject]) -> None:
    """Removes the temporary files of atomic writes that a stopped build left behind (a worker
    ended mid-object by build_pool._stop_workers, or a kill -9) from the library folder, the
    CoACD cache and the folders of the objects about to be built, so a resumed library holds
    the same files as one built in one go. Only for a folder this build alone writes (the
    objects command holds its lock)."""
    for folder in [out, out / ".coacd_cache", *(out / o.id for o in todo)]:
        for stale in folder.glob(".*.tmp"):
            stale.unlink(missing_ok=True)


def build_procedural(out: str | Path, num: int, seed: int, cfg: ProcessConfig | None = None,
                     progress: bool = True, split: str | None = None,
                     workers: int = 1) -> Manifest:
    """Builds (or resumes) the procedural library of `num` objects at `seed` in `out`.

    `split` ("train" or "unseen") builds only the objects of that split of the full build, each
    identical to its full-build self (an object's mesh and processing depend on (seed, id) only);
    their split is the full build's, computed over all `num` planned objects. That holds while
    no other object of their family is rejected (none of the 80 at seed 0 is): a rejection shrinks
    the family, which a full build would split anew. Building the rest later (the same command
    without `split`) completes the library. `workers` processes build objects side by side; the
    library is the same as a serial build's (each object depends on (seed, id) only, and the
    manifest lists them in plan order)."""
    from tqdm import tqdm

    out, cfg = Path(out), cfg or ProcessConfig()
    check_bounds(cfg)  # a hand-built ProcessConfig meets the rules a flag's value does
    if split not in (None, "train", "unseen"):
        raise InputError(f"split must be 'train' or 'unseen', got {split!r}")
    planned = planned_procedural(num)
    wanted = None
    if split is not None:
        assign_splits(planned, seed)
        wanted = {o.id for o in planned if o.split == split}
    # Without `split`, the split is over what was built, as always.
    plan = planned if split is not None else None
    out.mkdir(parents=True, exist_ok=True)
    manifest, timings = _load_or_new(out), _load_timings(out)
    todo = objects_to_build(planned, manifest, seed, wanted)
    _clear_stale_temporaries(out, todo)
    t0 = time.perf_counter()
    build = functools.partial(_build_planned, out, seed, cfg)
    # The bar counts only the objects still to build, so its rate and ETA hold on a resume or
    # a --split build.
    for built in tqdm(in_plan_order(build, todo, workers, name=lambda o: o.id), total=len(todo),
                      disable=not progress, desc="objects"):
        _append(manifest, timings, built)
        _save(out, manifest, seed, plan, timings)  # after every object: a killed run resumes here
    timings["build_s"] += time.perf_counter() - t0
    _save(out, manifest, seed, plan, timings)
    return manifest


# How a file name becomes an id, said in the refusal of two files that meet on one.
ID_RULE = "an id keeps the letters and digits of the path, makes other characters '_', and " \
          "ignores case"


def ingested_id(rel: str) -> str:
    """The object id of the mesh file `rel` (relative to the source folder): "mesh_" and its
    path without the extension, every character but letters and digits made "_". Also the name
    of the object's folder in the library."""
    name = Path(rel).with_suffix("").as_posix()
    return "mesh_" + "".join(c if c.isalnum() else "_" for c in name)


def ingested_ids(source: Path, files: list[Path], manifest: Manifest, out: Path) -> dict[str, str]:
    """{file relative to `source`: its object id} for the mesh files (supported extensions) of
    `files`; an InputError naming both files when two of them, or one of them and an object the
    library in `out` already holds from another file, would get the same id.

    Ids are file names made safe, so distinct files can meet on one: "cup a.obj" and
    "cup_a.obj", "cup.obj" and "cup.stl", "sub/cup.obj" and "sub_cup.obj". They are compared
    case-insensitively too: the id is also the object's folder, and "mesh_Cup" and "mesh_cup"
    are one folder on macOS's and Windows' file systems (a library built on Linux is copied
    there). Either object would overwrite the other's files. The build is refused rather than
    one id changed (a suffix, a hash): an id names the object in every report and card, so it
    should be the name the user gave, the same whichever files sit beside it and whatever order
    a resumed library was built in; renaming one file is a one-line fix the user controls."""
    # casefolded id -> (the file that has it, whether the library already holds its object)
    owners: dict[str, tuple[str, bool]] = {o.id.casefold(): (o.source, True)
                                           for o in manifest.objects}
    ids = {}
    for path in files:
        if path.suffix.lower() not in SUPPORTED:  # rejected with its reason, gets no id
            continue
        rel = str(path.relative_to(source))
        object_id = ids[rel] = ingested_id(rel)
        owner, built = owners.setdefault(object_id.casefold(), (rel, False))
        if owner == rel:  # this file, or its object built by an earlier run (a resume)
            continue
        if built:
            raise InputError(f"mesh folder {source}: {rel!r} would be object {object_id!r}, "
                             f"which library {out} already holds from {owner!r} ({ID_RULE}); "
                             "rename it")
        raise InputError(f"mesh folder {source}: {owner!r} and {rel!r} would both be object "
                         f"{object_id!r} ({ID_RULE}); rename one of them")
    return ids


def _forget(out: Path, manifest: Manifest, rel: str) -> None:
    """Drops what the library holds of mesh file `rel` (its object, folder and rejection)."""
    import shutil

    for obj in [o for o in manifest.objects if o.source == rel]:
        shutil.rmtree(out / obj.id, ignore_errors=True)
    manifest.objects = [o for o in manifest.objects if o.source != rel]
    manifest.rejected = [r for r in manifest.rejected if r.source != rel]


def ingest_folder(source: str | Path, out: str | Path, seed: int = 0,
                  cfg: ProcessConfig | None = None, progress: bool = True,
                  say: Callable[[str], None] | None = None) -> Manifest:
    """Every mesh file of `source` as an object of the library `out`, or its rejection. Each
    mesh's size rule (assets/mesh_scale.py: its size, unit and the scale applied; with
    cfg.keep_size its real size, or a rejection where it does not fit) is recorded in its entry
    and, with `say`, told in one line."""
    from tqdm import tqdm

    from corn_drake.assets.mesh_scale import size_rule

    source, out, cfg = Path(source), Path(out), cfg or ProcessConfig()
    check_bounds(cfg)
    if not source.is_dir():
        raise MissingInputError(f"mesh folder not found: {source}")
    files = find_mesh_files(source)
    if not any(p.suffix.lower() in SUPPORTED for p in files):
        # Refuse before making `out`: an empty library would only fail later, elsewhere.
        raise InputError(f"mesh folder {source}: no mesh files "
                         f"({', '.join(sorted(SUPPORTED))}) in it")
    manifest = _load_or_new(out)
    ids = ingested_ids(source, files, manifest, out)  # before anything is written
    out.mkdir(parents=True, exist_ok=True)
    timings = _load_timings(out)
    done = {o.source for o in manifest.objects} | {r.source for r in manifest.rejected}
    # Each mesh file's sha256 as it was built: a rerun rebuilds a file that changed since
    # instead of keeping the old shape (libraries from before this record are not checked).
    hashes = manifest.extra.setdefault("source_sha256", {})
    for path in tqdm(files, disable=not progress, desc="ingest"):
        rel = str(path.relative_to(source))
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        if rel in done and hashes.get(rel, digest) != digest:
            _forget(out, manifest, rel)
            if say is not None:
                say(f"{rel}: changed since library {out} built it (its sha256 differs): "
                    "built again")
        elif rel in done:
            continue
        hashes[rel] = digest
        obj_seed = zlib.crc32(f"{seed}:{rel}".encode())
        rng = np.random.default_rng(obj_seed)
        try:
            mesh, warnings = load_watertight(path)
            mesh, rule = size_rule(mesh, path.suffix, cfg)
        except Rejected as e:
            manifest.rejected.append(Rejection(rel, str(e)))
            _save(out, manifest, seed, timings=timings)
            continue
        object_id = ids[rel]
        warnings += [w for w in [rule.warning()] if w]
        entry = LibraryObject(id=object_id, source=rel, family=INGESTED_FAMILY, warnings=warnings)
        convex = bool(abs(mesh.volume - mesh.convex_hull.volume) < 1e-3 * mesh.volume)
        try:
            _add(out, manifest, timings, entry, rng, mesh, convex, cfg, out / ".coacd_cache")
        except Exception as e:  # one bad object must not end the run
            manifest.rejected.append(Rejection(rel, f"processing failed: {e}"))
        added = manifest.objects[-1] if manifest.objects else None
        if added is not None and added.source == rel:
            added.extra = {**added.extra, "scale": rule.record(added.radius)}
            if say is not None:
                say(rule.line(object_id, rel, added.radius, cfg))
        _save(out, manifest, seed, timings=timings)
    return manifest
