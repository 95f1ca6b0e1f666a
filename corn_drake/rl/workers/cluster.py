"""Where the Ray workers run, what reaches them there, and what a run says about it (issue 56).

- What each worker asks of Ray (`worker_cpus`) and how it is placed (`worker_options`).
- The object library's files travel through Ray's object store (`pack_library` on the driver,
  `arrive` in the worker): a worker on another node writes them once per node into a temp
  folder (rl/workers/node_library_cache.py), checks every object by content hash, and never
  opens the driver's paths. The encoder
  and the run's config already travel inside the actor's arguments (the pickled agent and the
  EnvFactory), so the library is the only file a worker needs.
- Which node every worker is on, and every death with its reason (`WorkerRecord`): one line on
  stdout per death, and the lot in metrics.json.

The learner is the driver process itself (Ray only places the workers), so it stays on the
node the command was started on.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import hashlib
import math
import os
import socket
import time
from pathlib import Path

import ray

from corn_drake.errors import InputError
from corn_drake.rl.workers.node_library_cache import node_copy

# Set by init_ray: True when this process joined a cluster (--ray-address), False when it started
# its own Ray. Decides what a worker asks for (worker_cpus).
joined_cluster = False

# Workers not started this long after their creation get one line (WorkerRecord.placed): a
# worker's start builds its envs, seconds on a busy core; a minute means it waits for room.
PLACEMENT_NOTICE_S = 60.0

# How often the room of a pending worker is checked again (wait_with_room): Ray
# marks a lost node dead seconds after its workers' deaths are seen.
ROOM_RECHECK_S = 2.0


class NoRoomForWorkers(InputError):
    """The cluster's live nodes cannot host the workers asked for (one line, exit 2; a run's
    checkpoint on disk is kept as it was)."""


def check_ray_address(address: str, flag: str = "--ray-address") -> None:
    """InputError (one line naming `flag`) unless a Ray cluster's head answers at `address`
    (HOST:PORT, ray://HOST:PORT, or auto: the cluster `ray start` left on this machine).

    Checked before any work: ray.init on an address where nothing listens retries for minutes
    before it fails (2 min and still retrying in a probe here). Only that something accepts a
    connection at the port is checked; ray.init says the rest."""
    import ray._private.services as services

    text = address.strip()
    if text == "auto":
        try:
            text = services.canonicalize_bootstrap_address_or_die("auto")
        except ConnectionError:
            raise InputError(f"{flag} auto: no Ray cluster found on this machine; start one "
                             f"with `ray start --head` or give HOST:PORT") from None
    host, _, port = text.removeprefix("ray://").rpartition(":")
    host = host.strip("[]")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise InputError(f"{flag} {address!r}: expected HOST:PORT of a Ray cluster's head "
                         f"(e.g. 10.0.0.5:6379, as `ray start --head` printed it)")
    if not text.startswith("ray://"):
        host = services.resolve_ip_for_localhost(host)  # where ray.init will connect
    try:
        socket.create_connection((host, int(port)), timeout=5.0).close()
    except OSError as e:
        reason = e.strerror or str(e) or type(e).__name__
        raise InputError(f"{flag} {address}: no Ray cluster answers at {host}:{port} ({reason}); "
                         f"start its head with `ray start --head --port {port}`, or leave "
                         f"{flag} out for a local Ray") from None


def worker_cpus(num_workers: int) -> float:
    """CPUs each worker asks Ray for: the core it keeps busy stepping its envs.

    On a cluster one each, so Ray puts no more workers on a node than it has cores (`ray start
    --num-cpus` says how many). This process's own Ray was started with the machine's usable
    cores; more workers than that share them, cores / workers each (Ray counts CPUs to 1e-4):
    oversubscribing a small machine is what a local run asks for (the project's machines give
    about one core), never what a cluster run gets without saying so."""
    if joined_cluster:
        return 1.0
    cores = ray.cluster_resources().get("CPU", 1.0)
    if num_workers <= cores:
        return 1.0
    return max(math.floor(cores / num_workers * 1e4) / 1e4, 1e-4)


def worker_options(cpus: float) -> dict:
    """Ray options of every worker actor.

    scheduling_strategy="SPREAD" per actor rather than a SPREAD placement group: SPREAD puts
    the workers on as many nodes as have room, so a lost node takes as few workers as can be,
    and a replacement after a node is lost goes to whichever node has room. A placement group
    keeps its bundles reserved and reschedules a lost bundle as a unit, so a replacement would
    wait for room in the group instead of using the nodes that are left."""
    return {"num_cpus": cpus, "scheduling_strategy": "SPREAD"}


def hosting_slots(cpus: float) -> int:
    """How many workers of `cpus` CPUs the live nodes can hold at once (node by node)."""
    return sum(int(node["Resources"].get("CPU", 0.0) / cpus + 1e-9)
               for node in ray.nodes() if node["Alive"])


def check_room(num_workers: int, cpus: float, what: str) -> None:
    """NoRoomForWorkers when the live nodes cannot host `num_workers` of `cpus` CPUs: Ray would
    leave the missing ones pending forever, and the run would hang instead of saying so."""
    slots = hosting_slots(cpus)
    if slots < num_workers:
        raise NoRoomForWorkers(f"{what}: the Ray cluster's live nodes have room for {slots} "
                               f"worker(s) of {cpus:g} CPU, {num_workers} needed: add nodes "
                               f"(ray start --address ... --num-cpus N) or run fewer --workers")


def wait_with_room(refs: list, needed: int, cpus: float, what: str,
                   waiting=lambda pending: None) -> None:
    """Waits until every ref in `refs` is ready (the workers have started), checking every
    ROOM_RECHECK_S that the live nodes still have room for `needed` workers of `cpus` CPUs
    (NoRoomForWorkers naming `what` when not) and calling `waiting(pending refs)`: a node lost
    while they are pending ends the wait instead of leaving it without end."""
    while True:
        _, pending = ray.wait(refs, num_returns=len(refs), timeout=ROOM_RECHECK_S)
        if not pending:
            return
        check_room(needed, cpus, what)
        waiting(pending)


class WorkerBase:
    """What every worker kind answers besides its work: its process and its node."""

    def pid(self) -> int:
        return os.getpid()

    def node(self) -> str:
        return ray.get_runtime_context().get_node_id()


def death_reason(error: Exception) -> str:
    """One line of why a worker died, from Ray's multi-line error ("its node has died", "its
    worker process has died", ...)."""
    if isinstance(error, ray.exceptions.ActorUnavailableError):
        return "it became unreachable"
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    # Ray's message: a heading ("The actor died unexpectedly ..."), "key: value" lines (class,
    # actor id, pid, ip), then the cause; the cause is the line worth printing.
    causes = [line for line in lines[1:]
              if line.split(":")[0] not in ("class_name", "actor_id", "pid", "name",
                                            "namespace", "ip")]
    line = (causes or lines or [type(error).__name__])[0]
    for heading in ("The actor is dead because ", "The actor died because "):
        if line.startswith(heading):
            line = line[len(heading):]
    return line.split(". ")[0].rstrip(".")[:200]


class WorkerRecord:
    """Which node each worker is on, and each replacement with its reason."""

    def __init__(self, kind: str):
        self.kind = kind
        self.nodes: list[str] = []
        self.deaths: list[dict] = []

    def placed(self, actors: list, cpus: float) -> None:
        """Waits for every worker to start and records its node. Workers still waiting after
        PLACEMENT_NOTICE_S are named in one line: Ray leaves a worker pending, silently, while
        the CPUs it asks for are held by others (check_room counts capacity, not use). The room
        is checked again while any is pending: a node lost meanwhile raises NoRoomForWorkers
        instead of a wait without end (spawn_replacement says why)."""
        refs = [a.node.remote() for a in actors]
        start, noticed = time.monotonic(), []

        def notice(pending: list) -> None:
            if not noticed and time.monotonic() - start >= PLACEMENT_NOTICE_S:
                free = ray.available_resources().get("CPU", 0.0)
                print(f"{len(pending)} {self.kind} worker(s) not started after "
                      f"{PLACEMENT_NOTICE_S:.0f} s ({free:g} CPUs free in the Ray cluster, "
                      f"each worker asks {cpus:g}): still waiting", flush=True)
                noticed.append(True)

        wait_with_room(refs, len(actors), cpus, f"{self.kind} workers", notice)
        self.nodes = ray.get(refs)

    def replaced(self, i: int, error: Exception, actor, during: str) -> None:
        """Records worker `i`'s death and its replacement `actor` (waited for), in one line."""
        reason = death_reason(error)
        try:
            new = ray.get(actor.node.remote())
        except ray.exceptions.RayActorError:  # died starting: the caller's next call says so
            new = "none (it died starting)"
        old = self.nodes[i]
        self.nodes[i] = new
        self.deaths.append({"worker": i, "node": old, "reason": reason,
                            "replacement_node": new, "during": during})
        print(f"{self.kind} worker {i} on node {old[:12]} died ({reason}); replaced on node "
              f"{new[:12]}, {during}", flush=True)

    def report(self) -> dict:
        """metrics.json's record of where the workers ran."""
        context = ray.get_runtime_context()
        return {"worker_nodes": list(self.nodes), "worker_restarts": list(self.deaths),
                "driver_node": context.get_node_id(), "ray_gcs_address": context.gcs_address,
                "ray_cluster_joined": joined_cluster}


def start_pool(pool, factory, num_workers: int, kind: str) -> None:
    """What every worker pool does first (rollout, segment, primitive): the library's files put
    in the object store once (read here: no node needs the driver's filesystem), each worker's
    CPUs and the room for them checked, the workers spawned by `pool._spawn(w)` and where they
    landed recorded. Sets pool._library, .cpus, .workers, .record and .restarts."""
    import ray

    pool._library = ray.put(pack_library(factory))
    pool.cpus = worker_cpus(num_workers)
    check_room(num_workers, pool.cpus, f"{kind} workers")
    pool.workers = [pool._spawn(w) for w in range(num_workers)]
    pool.record = WorkerRecord(kind)
    pool.record.placed(pool.workers, pool.cpus)
    pool.restarts = 0


def spawn_replacement(kind: str, workers: list, i: int, cpus: float, spawn) -> None:
    """`kind` worker `i` replaced by `spawn()`, waited for until it has started, when the live
    nodes have room for it beside the others (the slots of `workers` that are not None);
    NoRoomForWorkers otherwise, `workers[i]` left as it was.

    The room is checked again while the replacement is pending: a worker's death can reach the
    driver before Ray marks its node dead (a CI run here saw the replacement created 0.25 s
    before the node's death was known), so the first check may count a lost node's CPUs, and a
    replacement that fits nowhere would otherwise be waited for forever."""
    with contextlib.suppress(Exception):
        ray.kill(workers[i])  # an unreachable one must not come back beside its replacement
    needed, what = sum(w is not None for w in workers), f"replacing {kind} worker {i}"
    check_room(needed, cpus, what)
    actor = spawn()
    try:
        wait_with_room([actor.node.remote()], needed, cpus, what)
    except NoRoomForWorkers:
        ray.kill(actor)  # pending: it must not take a node's room when one joins
        raise
    workers[i] = actor


# --- the object library through the object store ------------------------------------------


@dataclasses.dataclass
class LibraryFiles:
    """What a run's envs read of their object library, as bytes: the manifest and every file of
    the objects the envs use, with each object's content hash (assets/content_hash.py)."""
    driver_node: str
    driver_path: str
    files: dict[str, bytes]
    hashes: dict[str, str]
    digest: str  # the cache folder's name: the same library content, the same folder


def pack_library(factory) -> LibraryFiles | None:
    """The library `factory`'s envs use, read on the driver; None when they use none (a box)."""
    obj = factory.teacher_config.scene.object
    if obj.kind != "library":
        return None
    return pack_objects(Path(obj.library),
                        factory.train_objects if obj.cycles_library else [obj.object_id])


def pack_objects(library: Path, ids) -> LibraryFiles:
    """The files of objects `ids` of `library` (and its manifest), read on the driver."""
    from corn_drake.assets.content_hash import combined_hash, object_hashes
    from corn_drake.assets.manifest import library_file, manifest_path, named_files, read_manifest

    library = Path(library)
    objects = {o.id: o for o in read_manifest(library).objects}
    files = {manifest_path(library).name: manifest_path(library).read_bytes()}
    for object_id in ids:
        for field, rel in named_files(objects[object_id]):
            files[rel] = library_file(library, objects[object_id], field, rel).read_bytes()
    hashes = object_hashes(library, ids)
    digest = hashlib.sha256(combined_hash(hashes).encode()
                            + files[manifest_path(library).name]).hexdigest()
    return LibraryFiles(ray.get_runtime_context().get_node_id(), str(library), files, hashes,
                        digest)


def library_here(library: LibraryFiles) -> Path:
    """The library's folder as this worker's node holds it: the driver's path on its node,
    else this node's checked copy."""
    if ray.get_runtime_context().get_node_id() == library.driver_node:
        return Path(library.driver_path)
    return node_copy(library)


def arrive(factory, library: LibraryFiles | None):
    """`factory` as this worker's node must use it: unchanged on the driver's node (its paths
    are this node's), else pointing at this node's copy of the library (written on first use,
    checked by content hash). The driver's path is never opened on another node."""
    if library is None or ray.get_runtime_context().get_node_id() == library.driver_node:
        return factory
    folder = node_copy(library)
    config = copy.deepcopy(factory.config)
    teacher = config.teacher if hasattr(config, "teacher") else config
    teacher.scene.object.library = str(folder)
    # A new EnvFactory: the driver's cached train_objects (read from its path) stays behind.
    return dataclasses.replace(factory, config=config)
