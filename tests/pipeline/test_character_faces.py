"""Morph targets travel through the character step and the bundle, so bundled riders move their
faces too; a morph array of the wrong shape is a FormatError naming the field."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def rider_arrays():
    from piste.character import default_rider
    from piste.pipeline.characters import character_arrays

    return character_arrays(default_rider(0))


def test_morphs_round_trip(rider_arrays):
    from piste.pipeline.characters import lods_from_arrays, model_from_arrays

    arrays, meta = rider_arrays
    assert meta["morphs"] == ["smile", "blink", "shout"]
    a = {f"characters/rider/{k}": v for k, v in arrays.items()}
    model = model_from_arrays(a, "characters/rider/", meta)
    lods = lods_from_arrays(a, "characters/rider/", meta, model)
    assert model.meshes[0].morph_names == meta["morphs"]
    for i, lod in enumerate(lods):
        mp = arrays[f"lod{i}/morph_positions"]
        assert mp.shape == (3, lod.mesh.n_vertices, 3)
        np.testing.assert_array_equal(lod.mesh.morph_positions, mp)
        assert np.abs(mp).sum() > 0  # every LOD keeps a face that moves


def test_bad_morph_shape_is_a_format_error(rider_arrays):
    from piste.errors import FormatError
    from piste.pipeline.characters import lods_from_arrays, model_from_arrays

    arrays, meta = rider_arrays
    a = {f"characters/rider/{k}": v for k, v in arrays.items()}
    a["characters/rider/lod1/morph_positions"] = a["characters/rider/lod1/morph_positions"][:, :5]
    model = model_from_arrays(a, "characters/rider/", meta)
    with pytest.raises(FormatError, match="lod1/morph_positions"):
        lods_from_arrays(a, "characters/rider/", meta, model)
