import numpy as np
import pytest

from piste.errors import FormatError, ValidationError
from piste.terrain import PatchNet
from piste.formats.bpt import read_bpt, write_bpt

from nets import TEAPOT, grid_net


def test_teapot_topology():
    net = PatchNet.from_bpt(TEAPOT)
    assert net.n_patches == 32
    sides = 32 * 4
    shared, boundary, degenerate = len(net.shared_edges), len(net.boundary_edges), int(net.edge_degenerate.sum())
    assert shared * 2 + boundary + degenerate == sides
    assert shared == 52  # 104 of the 128 patch sides are shared
    assert degenerate == 8  # lid apex and bottom centre: 4 collapsed sides each
    assert boundary == 16  # rim opening, lid rim, handle and spout ends


def test_grid_topology_and_flips():
    net = grid_net(5, 7, seed=2)
    assert len(net.shared_edges) == 4 * 7 + 5 * 6
    assert len(net.boundary_edges) == 2 * (5 + 7)
    # every shared edge's control points agree exactly in both patches
    for e in net.shared_edges:
        pts = []
        for slot in (0, 1):
            p, s = net.edge_patches[e, slot], net.edge_sides[e, slot]
            pts.append(net._side_points(p, s, net.side_flip[p, s]))
        assert np.array_equal(pts[0], pts[1])
        assert np.array_equal(pts[0], net.edge_cp[e])
    assert net.side_flip.any() and not net.side_flip.all()


def test_welding_snaps_within_tolerance():
    net = grid_net(2, 2, flips=False)
    cp = net.control_points.copy()
    cp[1, 0, 1] += 1e-9  # patch 1's side 3 (u=0) control point nudged within tolerance
    welded = PatchNet(cp, tol=1e-6)
    assert len(welded.shared_edges) == 4


def test_nan_names_patch_and_edge():
    cp = grid_net(2, 2).control_points.copy()
    cp[3, 0, 2, 1] = np.nan
    with pytest.raises(ValidationError, match=r"patch 3 edge 3 \(u=0\).*control point \[0\]\[2\]"):
        PatchNet(cp)
    cp = grid_net(2, 2).control_points.copy()
    cp[1, 1, 1, 0] = np.inf
    with pytest.raises(ValidationError, match="patch 1 interior"):
        PatchNet(cp)


def test_edge_shared_by_three_patches():
    net = grid_net(1, 2, flips=False)
    cp = np.concatenate([net.control_points, net.control_points[1:2] + [0, 0, 0]])
    cp[2, 1:3] += [0, 0, 5.0]  # a third patch on the same boundary as patch 1 but a different interior
    with pytest.raises(ValidationError, match="more than two patches"):
        PatchNet(cp)


def test_c0_violation_names_both_sides():
    net = grid_net(1, 2, flips=False)
    cp = net.control_points.copy()
    cp[1, 0, 1, 2] += 0.05  # patch 1's u=0 side no longer matches patch 0's u=1 side
    with pytest.raises(ValidationError, match=r"patch 0 edge 1 \(u=1\) and patch 1 edge 3 \(u=0\).*C0"):
        PatchNet(cp)


def test_shape_errors():
    with pytest.raises(ValidationError, match=r"\(n, 4, 4, 3\)"):
        PatchNet(np.zeros((2, 3, 4, 3)))


def test_save_load_lossless(tmp_path):
    net = grid_net(3, 4, seed=5)
    net.uv[:] = np.random.default_rng(0).random(net.uv.shape)
    path = tmp_path / "net.npz"
    net.save(path)
    back = PatchNet.load(path)
    assert np.array_equal(back.control_points, net.control_points)
    assert np.array_equal(back.uv, net.uv)
    assert np.array_equal(back.lightmap_rect, net.lightmap_rect)
    assert back.tol == net.tol
    assert np.array_equal(back.side_edge, net.side_edge)
    assert not list(tmp_path.glob(".*tmp"))


def test_load_errors(tmp_path):
    with pytest.raises(FormatError, match="no such file"):
        PatchNet.load(tmp_path / "missing.npz")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(FormatError, match="bad.npz"):
        PatchNet.load(bad)
    partial = tmp_path / "partial.npz"
    np.savez(partial, control_points=np.zeros((1, 4, 4, 3)))
    with pytest.raises(FormatError, match="field 'uv'"):
        PatchNet.load(partial)


def test_bpt_roundtrip(tmp_path):
    cp = read_bpt(TEAPOT)
    assert cp.shape == (32, 4, 4, 3)
    out = tmp_path / "t.bpt"
    write_bpt(out, cp)
    assert np.array_equal(read_bpt(out), cp)


@pytest.mark.parametrize(
    "text, line, what",
    [
        ("", 1, "empty"),
        ("x\n", 1, "patch count"),
        ("1\n3 3\n" + "0 0 0\n" * 15, 18, "end of file"),
        ("1\n2 3\n" + "0 0 0\n" * 16, 2, "bicubic"),
        ("1\n3 3\n" + "0 0 0\n" * 4 + "0 0\n" + "0 0 0\n" * 11, 7, "x y z"),
        ("1\n3 3\n" + "0 0 0\n" * 4 + "0 nan 0\n" + "0 0 0\n" * 11, 7, "finite"),
        ("1\n3 3\n" + "0 0 0\n" * 16 + "5\n", 19, "trailing"),
    ],
)
def test_bpt_errors_name_the_line(tmp_path, text, line, what):
    p = tmp_path / "bad.bpt"
    p.write_text(text)
    with pytest.raises(FormatError, match=rf"bad\.bpt, line {line}: .*{what}"):
        read_bpt(p)


def test_bounds_and_patch_bounds_are_the_control_points_extremes():
    """``bounds`` / ``patch_bounds`` (reduced over contiguous rows and halves, not numpy's strided
    3-wide reduction) give exactly the min/max of the control points, and follow edits in place
    (nothing cached that could go stale)."""
    net = PatchNet.from_bpt(TEAPOT)
    for _ in range(2):
        cp = net.control_points
        pts = cp.reshape(len(net), 16, 3)
        lo, hi = net.patch_bounds
        assert lo.shape == hi.shape == (len(net), 3) and lo.dtype == np.float64
        assert np.array_equal(lo, pts.min(1)) and np.array_equal(hi, pts.max(1))
        blo, bhi = net.bounds
        assert blo.shape == bhi.shape == (3,)
        assert np.array_equal(blo, cp.reshape(-1, 3).min(0)) and np.array_equal(bhi, cp.reshape(-1, 3).max(0))
        # every one of the 16 points and 3 axes can be the extreme: move one interior point of patch 5 far out
        net.control_points[5, 2, 1] += [-40.0, 50.0, 60.0]
    assert net.patch_bounds[0][5, 0] == net.control_points[5, 2, 1, 0] == net.bounds[0][0]
    assert net.patch_bounds[1][5, 2] == net.control_points[5, 2, 1, 2] == net.bounds[1][2]


@pytest.mark.parametrize("side", [0, 1, 2, 3])
def test_from_topology_sees_a_moved_point_on_each_side(side):
    """The stored-topology check reads each side's points (rows and columns of the 4x4 grid, taken as
    slices): a middle control point of any side of an inner patch moved breaks the shared edge."""
    from piste.terrain.net import SIDE_INDEX

    net = grid_net(3, 3, seed=1)
    topo = {k: v.copy() for k, v in net.topology().items()}
    again = PatchNet.from_topology(net.control_points.copy(), topo, uv=net.uv, lightmap_rect=net.lightmap_rect)
    assert np.array_equal(again.edge_cp, net.edge_cp) and again.tol == net.tol
    cp = net.control_points.copy()
    i, j = SIDE_INDEX[side][1]
    cp[4, i, j] += [0.0, 0.0, 0.25]  # patch 4: the middle one, every side shared
    with pytest.raises(ValidationError, match="two sides of a shared edge differ"):
        PatchNet.from_topology(cp, topo, uv=net.uv, lightmap_rect=net.lightmap_rect)


def test_default_tolerance_from_the_extent():
    net = PatchNet.from_bpt(TEAPOT)
    pts = net.control_points.reshape(-1, 3)
    assert net.tol == max(float(np.linalg.norm(pts.max(0) - pts.min(0))), 1.0) * 1e-6
