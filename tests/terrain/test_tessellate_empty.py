"""tessellate with nothing in view gives an empty mesh (issue 10 item 5), not a numpy error."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))  # for `from nets import ...`
import numpy as np
import pytest

from piste.terrain import tessellate

from nets import grid_net


@pytest.mark.parametrize("cache", [True, False])
@pytest.mark.parametrize("strips", [True, False])
def test_no_patches_gives_empty_mesh(cache, strips):
    net = grid_net(3, 3)
    mesh = tessellate(net, 6, patches=np.zeros(0, np.int64), strips=strips, cache=cache)
    assert mesh.n_triangles == 0 and mesh.n_vertices == 0
    assert mesh.positions.shape == (0, 3) and mesh.indices.shape == (0, 3)
    assert len(mesh.patch_ids) == 0 and list(mesh.vertex_start) == [0] and list(mesh.tri_start) == [0]
    assert (mesh.strips is not None) == strips
    # the same net still tessellates normally afterwards
    assert tessellate(net, 6, patches=[0], cache=cache).n_triangles == 50
