"""Procedural families: watertight, seeded, diverse; convex families need one hull."""

import numpy as np
import pytest

from corn_drake.assets.families import CONVEX_FAMILIES, FAMILIES, UNSEEN_FAMILIES, make_family_mesh


def test_at_least_twelve_families_with_held_out_ones():
    assert len(FAMILIES) >= 12
    assert UNSEEN_FAMILIES <= set(FAMILIES) and CONVEX_FAMILIES <= set(FAMILIES)


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_family_is_watertight_seeded_and_varied(family):
    a, b, c = (make_family_mesh(family, s) for s in (1, 1, 2))
    assert a.is_watertight and a.volume > 0
    np.testing.assert_array_equal(a.vertices, b.vertices)  # same seed, same mesh
    assert not np.allclose(a.extents, c.extents)  # another seed, another shape
    assert 0.01 < a.extents.max() < 0.4
    if family in CONVEX_FAMILIES:
        assert a.volume == pytest.approx(a.convex_hull.volume, rel=1e-6)


def test_unknown_family_is_named():
    with pytest.raises(ValueError, match="teapot"):
        make_family_mesh("teapot", 0)


@pytest.mark.parametrize("family, seed", [("mug", 0), ("bowl", 0), ("toy", 3), ("block", 1)])
def test_concave_family_hulls_stay_within_15_percent_of_the_mesh_volume(family, seed, tmp_path):
    from corn_drake.assets.processing.decompose import DecompositionConfig, decompose
    from corn_drake.assets.processing.process import normalise

    mesh = normalise(make_family_mesh(family, seed), 0.08)
    hulls, ratio, runs = decompose(mesh, DecompositionConfig(), tmp_path)
    assert len(hulls) <= 16 and runs in (1, 2)
    assert 0.99 < ratio <= 1.15, f"{family} seed {seed}: hull union {ratio:.3f} x mesh volume"
    # Cached: a second call makes no new CoACD result files and returns the same hulls.
    files = sorted(p.name for p in tmp_path.iterdir())
    again, ratio_again, _ = decompose(mesh, DecompositionConfig(), tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == files and ratio_again == ratio
