"""The unseen split: two whole held-out families plus a seeded share of every other family."""

from collections import Counter

import pytest

from corn_drake.assets.families import FAMILIES, UNSEEN_FAMILIES
from corn_drake.assets.manifest import LibraryObject
from corn_drake.assets.splits import assign_splits, held_out_count
from corn_drake.errors import InputError


def _procedural(num: int) -> list[LibraryObject]:
    """Library objects as build_procedural names them (families round-robin)."""
    families = sorted(FAMILIES)
    return [LibraryObject(id=f"{families[i % len(families)]}_{i // len(families):03d}",
                          family=families[i % len(families)]) for i in range(num)]


def _unseen(objects):
    return {o.id for o in objects if o.split == "unseen"}


def test_eighty_objects_hold_out_two_families_and_members_of_every_other():
    objects = _procedural(80)  # 5-6 members per family, as the full library
    assign_splits(objects, seed=0)
    by_family = {}
    for o in objects:
        by_family.setdefault(o.family, []).append(o)
    assert len(UNSEEN_FAMILIES) == 2
    for family, members in by_family.items():
        splits = Counter(o.split for o in members)
        if family in UNSEEN_FAMILIES:
            assert splits == {"unseen": len(members)}
            assert {o.unseen_group for o in members} == {"family"}
        else:
            # The old every-8th-member rule held out none of 5-6 members.
            assert splits["unseen"] >= 1 and splits["train"] >= 1, family
            assert {o.unseen_group for o in members if o.split == "unseen"} == {"member"}
        assert all(o.unseen_group is None for o in members if o.split == "train")
    member_unseen = sum(o.unseen_group == "member" for o in objects)
    assert 12 <= member_unseen <= 24  # about a fifth of the 68 non-held-out members


def test_split_is_deterministic_in_the_seed_and_the_seed_matters():
    a, b, c = _procedural(80), _procedural(80), _procedural(80)
    assign_splits(a, seed=3)
    assign_splits(b, seed=3)
    assign_splits(c, seed=4)
    assert _unseen(a) == _unseen(b)
    assert _unseen(a) != _unseen(c)
    # The seed picks members, never the held-out families.
    assert {o.family for o in c if o.unseen_group == "family"} == UNSEEN_FAMILIES


def test_resplitting_in_another_order_gives_the_same_split():
    """The library re-applies the rule over the manifest after every object."""
    objects = _procedural(40)
    assign_splits(objects, seed=1)
    shuffled = [LibraryObject(id=o.id, family=o.family) for o in reversed(objects)]
    assign_splits(shuffled, seed=1)
    assert _unseen(shuffled) == _unseen(objects)


def test_small_families_train_on_all_members_and_large_ones_keep_training_members():
    assert [held_out_count(n) for n in range(1, 7)] == [0, 0, 1, 1, 1, 1]
    assert held_out_count(20) == 4
    assert held_out_count(3, fraction=0.9) == 2  # at least one member always trains
    objects = _procedural(28)  # two members per family
    assign_splits(objects, seed=0)
    assert all(o.split == "train" for o in objects if o.family not in UNSEEN_FAMILIES)


def test_ingested_meshes_get_their_own_group():
    objects = [LibraryObject(id=f"mesh_{i}", family="ingested") for i in range(10)]
    assign_splits(objects, seed=0)
    groups = Counter(o.unseen_group for o in objects)
    assert groups == {None: 8, "ingested": 2}


def test_bad_entries_and_fractions_are_named():
    with pytest.raises(InputError, match="family"):
        assign_splits([LibraryObject(id="cuboid_000")], seed=0)
    with pytest.raises(InputError, match="fraction"):
        held_out_count(5, fraction=1.0)


def test_objects_command_summary_counts_unseen_by_group():
    from corn_drake.commands.datasets.objects import _split_summary

    objects = _procedural(80)
    assign_splits(objects, seed=0)
    groups = Counter(o.unseen_group for o in objects)
    summary = _split_summary(objects)
    assert summary.startswith(f"{groups[None]} train + {80 - groups[None]} unseen objects")
    assert f"{groups['family']} of held-out families" in summary
    assert f"{groups['member']} held-out members of seen families" in summary
