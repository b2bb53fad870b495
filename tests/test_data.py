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


def test_frozen_classes_hash_as_the_generated_method_does():
    from piste._data import FrozenDataMethods

    @dataclass(frozen=True)
    class Generated:
        a: int
        b: tuple = ()
        not_compared: float = field(default=0.0, compare=False)
        not_hashed: str = field(default="x", hash=False)

    @dataclass(frozen=True, repr=False, eq=False)
    class Shared(FrozenDataMethods):
        a: int
        b: tuple = ()
        not_compared: float = field(default=0.0, compare=False)
        not_hashed: str = field(default="x", hash=False)

    for args in [(1,), (2, (1, 2)), (3, (), 4.5, "y")]:
        g, s = Generated(*args), Shared(*args)
        assert hash(s) == hash(g) and repr(s) == repr(g).replace("Generated", "Shared", 1)
        assert s == Shared(*args) and {s: 1}[Shared(*args)] == 1
    assert Shared(1, (), 9.0) == Shared(1) and Shared(1, (), 0.0, "z") != Shared(1)
    with pytest.raises(dataclasses.FrozenInstanceError):
        Shared(1).a = 2  # type: ignore[misc]


def test_pistes_lights_keep_their_hash_and_equality():
    from piste.scene_data import AmbientLight, Lights, PointLight

    a, b = PointLight((0.0, 0.0, 1.0), (1.0, 1.0, 1.0), 1.0), PointLight((0.0, 0.0, 1.0), (1.0, 1.0, 1.0), 1.0)
    assert a == b and hash(a) == hash(b) and len({a, b}) == 1 and a != PointLight((0.0, 0.0, 2.0), (1.0, 1.0, 1.0), 1.0)
    lights = Lights((AmbientLight((1.0, 1.0, 1.0), 0.5), a))
    assert lights == Lights((AmbientLight((1.0, 1.0, 1.0), 0.5), b)) and hash(lights) == hash(Lights((AmbientLight((1.0, 1.0, 1.0), 0.5), b)))
    assert repr(a).startswith("PointLight(position=(0.0, 0.0, 1.0), color=(1.0, 1.0, 1.0), intensity=1.0")
