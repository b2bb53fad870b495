"""glTF lives in one subpackage, ``piste.formats.gltf`` (read, write, extensions, schema, checks);
the old module names are thin re-exports of the same objects, so existing code keeps working."""

from __future__ import annotations

import importlib

import pytest

OLD_TO_NEW = {
    "piste.formats.gltf_export": "piste.formats.gltf.write",
    "piste.formats.gltf_ext": "piste.formats.gltf.extensions",
    "piste.formats.gltf_schema": "piste.formats.gltf.schema",
    "piste.formats.gltf_checks": "piste.formats.gltf.checks",
}


@pytest.mark.parametrize("old", sorted(OLD_TO_NEW))
def test_the_old_module_names_re_export_the_same_objects(old):
    a, b = importlib.import_module(old), importlib.import_module(OLD_TO_NEW[old])
    assert a.__all__ == b.__all__
    public = [n for n in vars(b) if not n.startswith("_") and getattr(b, n).__class__.__name__ != "module"
              and getattr(getattr(b, n), "__module__", b.__name__) == b.__name__
              and n != "TYPE_CHECKING"]  # (typing's flag, imported for type-only imports: not the module's API)
    assert public, old
    for name in public:
        assert getattr(a, name) is getattr(b, name), f"{old}.{name}"


def test_the_package_names_the_reader_and_the_writer():
    import piste.formats.gltf as gltf
    from piste.formats import load_gltf
    from piste.formats.gltf.read import load_gltf as read_load
    from piste.formats.gltf.write import export_gltf

    assert gltf.load_gltf is load_gltf is read_load
    assert gltf.export_gltf is export_gltf
    assert gltf.precheck_gltf.__module__ == "piste.formats.gltf.schema"
