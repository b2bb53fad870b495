"""The terrain's topology stored in the bundle (issue 23 item 4): the build writes it, a load takes it
(checked, not recomputed) and gets the same net; old bundles without it still load; a damaged or
mismatched stored topology is a FormatError naming the member."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import FormatError, ValidationError
from piste.formats.bundle import TOPOLOGY_MEMBERS, read_bundle, write_bundle
from piste.pipeline.bundle_objects import load_bundle
from piste.terrain.net import TOPOLOGY_ARRAYS, TOPOLOGY_FORMAT, PatchNet

from tests.pipeline.conftest import SMALL_SCENE, write_hill
from tests.terrain.nets import TEAPOT, grid_net

FIELDS = ("control_points", "uv", "lightmap_rect", "side_edge", "side_flip", "edge_cp", "edge_patches", "edge_sides",
          "edge_degenerate", "corner_ids")


def _same_net(a: PatchNet, b: PatchNet) -> None:
    for k in FIELDS:
        x, y = getattr(a, k), getattr(b, k)
        assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y), k
    assert a.tol == b.tol


def _bundle(tmp_path, net: PatchNet, topology=True, edit=None, name="b.piste"):
    arrays = {"terrain/control_points": net.control_points, "terrain/uv": net.uv,
              "lightmap/atlas": np.full((4, 4, 3), 0.5, np.float32), "lightmap/rects": net.lightmap_rect}
    terrain = {"name": "t", "tol": net.tol, "patches": len(net)}
    if topology:
        arrays.update({f"terrain/{k}": v.copy() for k, v in net.topology().items()})
        terrain["topology"] = TOPOLOGY_FORMAT
    if edit is not None:
        edit(arrays, terrain)
    return write_bundle(tmp_path / name, {"name": "t", "terrain": terrain}, arrays)


def test_the_format_and_the_terrain_name_the_same_arrays():
    assert set(TOPOLOGY_MEMBERS) == {f"terrain/{k}" for k in TOPOLOGY_ARRAYS}
    for k, (dtype, shape) in TOPOLOGY_ARRAYS.items():
        want, ndim, last = TOPOLOGY_MEMBERS[f"terrain/{k}"]
        assert np.dtype(dtype).str == want and len(shape) == ndim and (shape[-1] if len(shape) == 2 else None) == last


@pytest.mark.parametrize("make", [lambda: PatchNet.from_bpt(TEAPOT), lambda: grid_net(5, 7, seed=3)],
                         ids=["teapot", "grid-with-flips"])
def test_from_topology_is_the_computed_net(make):
    """Degenerate edges (the teapot's lid and bottom), open boundaries and reversed sides."""
    net = make()
    again = PatchNet.from_topology(net.control_points, {k: v.copy() for k, v in net.topology().items()}, uv=net.uv,
                                   lightmap_rect=net.lightmap_rect, tol=net.tol, name=net.name)
    _same_net(net, again)
    assert PatchNet(net.control_points, tol=net.tol).n_edges == again.n_edges  # the next net computes again


def test_a_bundle_with_and_without_its_topology_loads_the_same_net(tmp_path):
    net = grid_net(4, 6, seed=1)
    new, old = _bundle(tmp_path, net), _bundle(tmp_path, net, topology=False, name="old.piste")
    a, b = load_bundle(new), load_bundle(old)
    assert "terrain/side_edge" in a.arrays and "terrain/side_edge" not in b.arrays
    _same_net(a.net, b.net)


def _set(key, fn):
    def edit(arrays, terrain):
        arrays[f"terrain/{key}"] = fn(arrays[f"terrain/{key}"])
    return edit


def _swap_first_two_edges(a):
    a = a.copy()
    a[[0, 1]] = a[[1, 0]]
    return a


def _renumber_edges(arrays, terrain):
    for k in ("edge_patches", "edge_sides", "edge_degenerate"):
        arrays[f"terrain/{k}"] = _swap_first_two_edges(arrays[f"terrain/{k}"])


def _flip_one(a):
    a = a.copy()
    a[0, 0] = ~a[0, 0]
    return a


def _flag_a_border_edge_degenerate(arrays, terrain):
    a = arrays["terrain/edge_degenerate"].copy()
    a[int(np.flatnonzero(arrays["terrain/edge_patches"][:, 1] < 0)[0])] = True
    arrays["terrain/edge_degenerate"] = a


@pytest.mark.parametrize("edit, member", [
    (_set("side_edge", lambda a: np.roll(a, 1)), "side_edge"),  # sides on the wrong edges
    (_set("side_edge", lambda a: a + 10**6), "side_edge"),  # out of range
    (_renumber_edges, "side_edge"),  # edges renumbered, side_edge not
    (_set("side_flip", _flip_one), "side_flip"),  # a side runs the wrong way along its edge
    (_set("edge_degenerate", lambda a: np.ones_like(a)), "edge_degenerate"),
    (_flag_a_border_edge_degenerate, "edge_degenerate"),  # one side only: its four points must be equal
    (_set("corner_ids", lambda a: np.zeros_like(a)), "corner_ids"),
    (_set("edge_sides", lambda a: a + 5), "edge_sides"),
])
def test_a_stored_topology_that_does_not_match_is_a_format_error(tmp_path, edit, member):
    """Checksums cover the arrays, so only a hand-made bundle gets here: still a clear error naming
    the member, never an IndexError in the renderer or a silently cracked terrain."""
    net = grid_net(3, 4, seed=2)
    with pytest.raises(FormatError, match="stored topology") as exc:
        load_bundle(_bundle(tmp_path, net, edit=edit))
    assert exc.value.field == f"terrain/{member}.npy"


@pytest.mark.parametrize("edit, match", [
    (lambda arrays, terrain: arrays.pop("terrain/corner_ids"), "member missing"),
    (_set("side_edge", lambda a: a.astype(np.int64)), "expected a"),
    (_set("side_flip", lambda a: a[:-1]), "expected a"),
    (_set("edge_patches", lambda a: a[:, :1]), "expected a"),
])
def test_declared_topology_members_are_checked_when_read(tmp_path, edit, match):
    with pytest.raises(FormatError, match=match) as exc:
        read_bundle(_bundle(tmp_path, grid_net(2, 2), edit=edit))
    assert exc.value.field.startswith("terrain/") and exc.value.field.endswith(".npy")


def test_the_manifest_field_is_schema_checked(tmp_path):
    def edit(arrays, terrain):
        terrain["topology"] = "one"
    with pytest.raises(FormatError, match="terrain.topology"):
        read_bundle(_bundle(tmp_path, grid_net(2, 2), edit=edit))


def test_another_topology_version_is_recomputed(tmp_path):
    """A future layout (``terrain.topology`` 2) is not trusted: the load computes the topology."""
    net = grid_net(3, 3, seed=4)

    def edit(arrays, terrain):
        terrain["topology"] = TOPOLOGY_FORMAT + 1
        arrays["terrain/side_edge"] = np.zeros_like(arrays["terrain/side_edge"])  # would fail the check
    _same_net(load_bundle(_bundle(tmp_path, net, edit=edit)).net, net)


def test_from_topology_checks_its_input():
    net = grid_net(2, 2, flips=False)
    topo = net.topology()
    with pytest.raises(ValidationError, match="corner_ids: missing"):
        PatchNet.from_topology(net.control_points, {k: v for k, v in topo.items() if k != "corner_ids"})
    moved = net.control_points.copy()
    moved[0, 3, 1, 2] += 1.0  # a point on a shared edge of patch 0 no longer welded to its neighbour's
    with pytest.raises(ValidationError, match="two sides of a shared edge differ"):
        PatchNet.from_topology(moved, topo)


def test_the_build_stores_the_topology(tmp_path):
    from piste.pipeline.build import build_scene

    write_hill(tmp_path)
    scene = tmp_path / "s.toml"
    scene.write_text(SMALL_SCENE.format(riders="", extra=""))
    out = build_scene(scene, out=tmp_path / "s.piste", cache_dir=tmp_path / "cache").path
    data = read_bundle(out)
    assert data.manifest["terrain"]["topology"] == TOPOLOGY_FORMAT
    b = load_bundle(out)
    computed = PatchNet(data.arrays["terrain/control_points"], uv=data.arrays["terrain/uv"],
                        lightmap_rect=data.arrays["lightmap/rects"], tol=data.manifest["terrain"]["tol"])
    for k in TOPOLOGY_ARRAYS:
        assert np.array_equal(data.arrays[f"terrain/{k}"], getattr(computed, k)), k
    _same_net(b.net, computed)


def test_the_terrain_members_are_read_first_and_handed_over(tmp_path):
    """read_bundle(on_terrain=) gets the net's members (and its topology) before the others are read,
    so load_bundle(warm=True) starts the vertex blocks while the light map etc. are still being read."""
    net = grid_net(3, 3, seed=5)
    path = _bundle(tmp_path, net)
    seen = []
    data = read_bundle(path, on_terrain=lambda man, arrays: seen.append((man["terrain"]["patches"], sorted(arrays))))
    assert len(seen) == 1
    patches, names = seen[0]
    assert patches == len(net) and "lightmap/atlas" not in names and "lightmap/atlas" in data.arrays
    assert set(names) == {"terrain/control_points", "terrain/uv", "lightmap/rects", *TOPOLOGY_MEMBERS}


def test_load_bundle_warm_uses_the_net_it_made_early(tmp_path):
    from piste.terrain.resident import resident_terrain

    b = load_bundle(_bundle(tmp_path, grid_net(3, 3, seed=6)), warm=True)
    jobs = {**b.net.__dict__.get("_resident", {}), **b.net.__dict__.get("_resident_pending", {})}
    assert jobs, "no vertex-block build was started for the bundle's net"
    assert resident_terrain(b.net, wait=True) is not None
    _same_net(b.net, grid_net(3, 3, seed=6))


def test_a_corrupt_later_member_still_fails_after_the_early_net(tmp_path):
    import zipfile

    path = _bundle(tmp_path, grid_net(2, 2))
    with zipfile.ZipFile(path) as zf:
        parts = {n: zf.read(n) for n in zf.namelist()}
    atlas = bytearray(parts["lightmap/atlas.npy"])
    atlas[-1] ^= 0xFF
    parts["lightmap/atlas.npy"] = bytes(atlas)
    bad = tmp_path / "bad.piste"
    with zipfile.ZipFile(bad, "w") as zf:
        for n, d in parts.items():
            zf.writestr(n, d)
    with pytest.raises(FormatError, match="checksum") as exc:
        load_bundle(bad, warm=True)
    assert exc.value.field == "lightmap/atlas.npy"
