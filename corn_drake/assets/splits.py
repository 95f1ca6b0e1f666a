"""Which library objects are unseen, and of which kind.

"Unseen" has to test two things: new shapes of a kind the policy trained on (held-out *members*
of a family) and kinds it never saw (held-out *families*). Every object of a family in
UNSEEN_FAMILIES is unseen (group "family"); of every other family, MEMBER_FRACTION of its members
(rounded, and at least one once the family has MIN_MEMBERS_FOR_HOLDOUT) is unseen (group
"member"). Ingested meshes form one family, "ingested", split by the same share (group
"ingested": each is a new shape, not a variant of a trained one).

The choice is a pure function of (seed, the objects' ids and families): the library re-applies it
to the whole manifest after every object, so a resumed or extended build ends with the split a
single build would give. Members are ranked by a hash of (seed, id), so a seed picks a different
share without touching the held-out families.
"""

from __future__ import annotations

import zlib
from collections import defaultdict

from corn_drake.assets.families import UNSEEN_FAMILIES
from corn_drake.assets.manifest import LibraryObject
from corn_drake.errors import InputError

INGESTED_FAMILY = "ingested"
MEMBER_FRACTION = 0.2
MIN_MEMBERS_FOR_HOLDOUT = 3  # a family of 1-2 members keeps them all for training
GROUPS = ("family", "member", INGESTED_FAMILY)


def held_out_count(members: int, fraction: float = MEMBER_FRACTION) -> int:
    """How many of a (not held-out) family's members are unseen."""
    if not 0.0 <= fraction < 1.0:
        raise InputError(f"member fraction must be in [0, 1), got {fraction}")
    if members < MIN_MEMBERS_FOR_HOLDOUT:
        return 0
    # round() keeps the share near `fraction`; max(1, ...) is the "every family" promise; the
    # min keeps at least one member for training.
    return min(members - 1, max(1, round(fraction * members)))


def _rank_key(seed: int, object_id: str) -> tuple[int, str]:
    return zlib.crc32(f"{seed}:split:{object_id}".encode()), object_id


def assign_splits(objects: list[LibraryObject], seed: int, fraction: float = MEMBER_FRACTION) -> None:
    """Sets `split` ("train" | "unseen") and `unseen_group` (a GROUPS entry, None for train) on
    each library object in place; objects need an `id` and a `family`."""
    by_family: dict[str, list[LibraryObject]] = defaultdict(list)
    for o in objects:
        if not o.family:
            raise InputError(f"manifest entry {o.id!r} has no 'family'")
        by_family[o.family].append(o)
    for family, members in by_family.items():
        if family in UNSEEN_FAMILIES:
            unseen, group = members, "family"
        else:
            ranked = sorted(members, key=lambda o: _rank_key(seed, o.id))
            unseen = ranked[:held_out_count(len(members), fraction)]
            group = INGESTED_FAMILY if family == INGESTED_FAMILY else "member"
        unseen_ids = {o.id for o in unseen}
        for o in members:
            held = o.id in unseen_ids
            o.split = "unseen" if held else "train"
            o.unseen_group = group if held else None
