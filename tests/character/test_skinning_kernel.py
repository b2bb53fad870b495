"""The compiled blended-palette skinning kernel gives the scipy reference's bits."""

import numpy as np
import pytest

from piste import _jit
from piste.character import default_rider
from piste.character import skinning
from piste.character.skinning import BlendedMesh


@pytest.mark.skipif(skinning._blend_nb is None, reason="numba not installed: only the scipy/numpy path exists")
@pytest.mark.parametrize("normalize", [True, False])
def test_compiled_blend_bit_identical_to_sparse(normalize):
    _jit.warm_up()
    assert skinning._blend_nb.ready()  # else the default call below would run numpy
    rider = default_rider()
    sk, me = rider.skeleton, rider.meshes[0]
    mats = np.stack([sk.skin_matrices(rider.clips[n].sample(0.3 * i + 0.1, loop=True))
                     for i, n in enumerate(["ride", "grab", "spin"])])
    bm = BlendedMesh.build(me, 0.25, 3)
    a = bm.apply_many(mats, normalize=normalize)
    b = bm.apply_many(mats, normalize=normalize, use_numba=False)
    assert a[0].dtype == np.float32 and a[0].shape == (3, me.n_vertices, 3)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    one = bm.apply(mats[1], normalize=normalize)
    ref = bm.apply(mats[1], normalize=normalize, use_numba=False)
    assert np.array_equal(one[0], ref[0]) and np.array_equal(one[1], ref[1])
