"""piste._data.DataMethods: the repr and == that @dataclass would generate, written once."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import pytest

from piste._data import DataMethods


def _pair():
    @dataclass
    class Generated:
        a: int
        b: list = field(default_factory=list)
        hidden: str = field(default="x", repr=False)
        ignored: float = field(default=0.0, compare=False)
        ref: object = None

    @dataclass(repr=False, eq=False)
    class Shared(DataMethods):
        a: int
        b: list = field(default_factory=list)
        hidden: str = field(default="x", repr=False)
        ignored: float = field(default=0.0, compare=False)
        ref: object = None

    return Generated, Shared


def test_the_same_repr_and_equality_as_the_generated_methods():
    G, S = _pair()
    for args in [(1,), (2, [1, 2]), (3, [], "y", 4.5)]:
        g, s = G(*args), S(*args)
        assert repr(s) == repr(g).replace("Generated", "Shared", 1)
        assert (s == S(*args)) == (g == G(*args)) is True
    g, s = G(1, ignored=1.0), S(1, ignored=1.0)  # compare=False fields are not compared
    assert (g == G(1)) and (s == S(1)) and not (s == S(2)) and s != S(1, hidden="z")
    assert S(1).__eq__(G(1)) is NotImplemented and S(1) != G(1)  # only the very same class
    g.ref, s.ref = g, s  # a reference back: "..."
    assert repr(s) == repr(g).replace("Generated", "Shared", 2) and repr(s).endswith("ref=...)")
    with pytest.raises(TypeError):
        hash(s)  # like a data class with eq: no hash
    assert dataclasses.fields(s) and dataclasses.replace(s, a=5).a == 5


def test_pistes_mutable_data_classes_use_it():
    from piste.character.model import Skeleton
    from piste.character.pose import Pose
    from piste.pipeline.bundle_objects import Bundle
    from piste.scene_data import Camera
    from piste.terrain.net import PatchNet

    for cls in (Pose, Skeleton, Camera, PatchNet, Bundle):
        assert cls.__repr__ is DataMethods.__repr__ and cls.__eq__ is DataMethods.__eq__ and cls.__hash__ is None
    p = Pose(np.zeros((1, 3)), np.array([[0.0, 0.0, 0.0, 1.0]]), np.ones((1, 3)))
    assert repr(p).startswith("Pose(translation=array([[0., 0., 0.]]), rotation=")
    assert p == p and p != "pose"  # (two poses of other arrays raise, as the generated == does)
