"""piste build's steps are a registry (piste.pipeline.build.BUILD_STEPS): build_scene walks it, a
registered step is run, cached under its content key and stored in the bundle; a scene section and a
build step registered together are a new feature in two small functions."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

from piste.errors import ConfigError
from piste.pipeline.build import (BUILD_STEPS, BuildContext, BuildStep, StepOutput, build_scene, register_step,
                                  unregister_step)
from piste.pipeline.bundle_objects import load_bundle
from piste.pipeline.cache import content_key
from piste.world.scene_file import SceneFile, SceneSection, SceneTable, register_section, unregister_section


def _height_step(calls: list) -> BuildStep:
    """A step reading the terrain: the net's highest control point, as an array and in the manifest."""

    def key(ctx: BuildContext) -> str:
        return content_key("test-step/1", ctx.terrain_key)

    def make(ctx: BuildContext) -> StepOutput:
        calls.append(ctx.scene.name)
        top = float(np.asarray(ctx.net.control_points)[..., 2].max())
        return {"top": np.array([top])}, {"top": top}

    def store(ctx: BuildContext, out: StepOutput) -> None:
        ctx.arrays["height/top"] = out[0]["top"]
        ctx.manifest["height"] = out[1]

    return BuildStep("height", "terrain key", key, make, store)


def test_build_walks_the_registry_in_order(small_scene):
    r = build_scene(small_scene())
    assert list(r.steps) == [s.name for s in BUILD_STEPS if s.cache] + ["write"]
    assert load_bundle(r.path).manifest["inputs"].keys() == {s.name for s in BUILD_STEPS if s.cache}


def test_a_registered_step_is_run_cached_and_stored(small_scene):
    scene = small_scene()
    plain = build_scene(scene, out=scene.with_name("plain.piste")).path.read_bytes()
    calls: list = []
    register_step(_height_step(calls), after="terrain")
    try:
        assert [s.name for s in BUILD_STEPS][:2] == ["terrain", "height"]
        r1 = build_scene(scene)
        assert "height" in r1.rebuilt and calls == ["small"]
        b = load_bundle(r1.path)
        top = float(b.arrays["height/top"][0])
        assert top == pytest.approx(np.asarray(b.net.control_points)[..., 2].max())
        assert b.manifest["height"] == {"top": top} and b.manifest["inputs"]["height"] == r1.steps["height"]["key"]
        r2 = build_scene(scene)  # from the cache: not made again, the same bytes
        assert "height" in r2.cached and calls == ["small"]
        assert r2.path.read_bytes() == r1.path.read_bytes()
        # the terrain changes: its key changes, the step runs again
        scene.write_text(scene.read_text().replace('source = "hill.npz"', 'source = "hill.npz"\nheight_offset = 5.0'))
        r3 = build_scene(scene)
        assert "height" in r3.rebuilt and calls == ["small", "small"]
        assert float(load_bundle(r3.path).arrays["height/top"][0]) == pytest.approx(top + 5.0)
    finally:
        unregister_step("height")
    assert "height" not in [s.name for s in BUILD_STEPS]
    scene.write_text(scene.read_text().replace("\nheight_offset = 5.0", ""))
    r4 = build_scene(scene)  # unregistered: the bundle of before, byte for byte
    assert "height" not in r4.steps and r4.path.read_bytes() == plain
    with zipfile.ZipFile(r4.path) as zf:
        assert "height/top.npy" not in zf.namelist()


def test_steps_parameter_runs_those_steps(small_scene):
    calls: list = []
    steps = list(BUILD_STEPS)
    steps.insert(1, _height_step(calls))
    r = build_scene(small_scene(), steps=steps, use_cache=False)
    assert calls == ["small"] and "height" in r.rebuilt and "height" not in [s.name for s in BUILD_STEPS]
    assert "height/top" in load_bundle(r.path).arrays


def test_a_step_with_nothing_to_do_is_recorded_as_none(small_scene):
    absent: list = []
    step = BuildStep("never", "nothing", key=lambda ctx: None, make=lambda ctx: ({}, {}),
                     store=lambda ctx, out: None, absent=lambda ctx: absent.append(True))
    r = build_scene(small_scene(riders=False), steps=[*BUILD_STEPS, step], use_cache=False)
    assert r.steps["never"] == {"cached": True, "seconds": 0.0, "key": "none"} and absent == [True]
    assert r.steps["characters"]["key"] == "none"  # no riders: the built-in step says so the same way


def test_a_section_and_a_step_make_a_feature(small_scene):
    """A new scene key reaching the bundle: one registered section, one registered step."""

    def parse(t: SceneTable, scene: SceneFile) -> float:
        t.allow({"depth"})
        return t.get("depth", "pos", 0.1)

    def key(ctx: BuildContext) -> str:
        return content_key("snow/1", ctx.scene.sections["snow"])

    def make(ctx: BuildContext) -> StepOutput:
        return {"depth": np.full(len(ctx.net), ctx.scene.sections["snow"], np.float32)}, {}

    def store(ctx: BuildContext, out: StepOutput) -> None:
        ctx.arrays["snow/depth"] = out[0]["depth"]

    register_section(SceneSection("snow", parse))
    register_step(BuildStep("snow", "[snow] depth", key, make, store))
    try:
        scene = small_scene(extra="\n[snow]\ndepth = 0.25\n")
        b = load_bundle(build_scene(scene).path)
        assert b.arrays["snow/depth"].shape == (len(b.net),) and np.all(b.arrays["snow/depth"] == 0.25)
    finally:
        unregister_step("snow")
        unregister_section("snow")


def test_register_refuses_mistakes():
    with pytest.raises(ConfigError, match="registered already"):
        register_step(BuildStep("terrain", "", lambda ctx: "k", lambda ctx: ({}, {}), lambda ctx, out: None))
    with pytest.raises(ConfigError, match="no build step 'bake'"):
        register_step(BuildStep("x", "", lambda ctx: "k", lambda ctx: ({}, {}), lambda ctx, out: None), after="bake")
    with pytest.raises(ConfigError, match="give run, or make and store"):
        BuildStep("x", "")
    with pytest.raises(ConfigError, match="no build step 'x'"):
        unregister_step("x")
    assert "x" not in [s.name for s in BUILD_STEPS]


def _unannotated(module) -> list[str]:
    """Public functions and methods of ``module.__all__`` with a parameter or return not annotated."""
    import inspect

    out = []
    for name in module.__all__:
        obj = getattr(module, name)
        funcs = [(name, obj)] if inspect.isfunction(obj) else [
            (f"{name}.{k}", v) for k, v in vars(obj).items()
            if inspect.isfunction(v) and (not k.startswith("_") or k == "__init__")] if inspect.isclass(obj) else []
        for label, f in funcs:
            sig = inspect.signature(f)
            missing = [p for p, v in sig.parameters.items() if p not in ("self", "cls") and v.annotation is v.empty]
            if missing or sig.return_annotation is sig.empty:
                out.append(f"{label}({', '.join(missing)})" + (" -> ?" if sig.return_annotation is sig.empty else ""))
    return out


def test_the_registries_public_api_is_typed_and_checked_strictly():
    import tomllib
    from pathlib import Path

    import piste.pipeline.build as build
    import piste.world.scene_file as scene_file

    assert _unannotated(build) == [] and _unannotated(scene_file) == []
    cfg = tomllib.loads((Path(__file__).resolve().parents[2] / "pyproject.toml").read_text())["tool"]["mypy"]
    strict = [o for o in cfg.get("overrides", []) if {"piste.pipeline.build", "piste.world.scene_file"} <= set(o["module"])]
    assert strict and strict[0]["disallow_untyped_defs"] and strict[0]["check_untyped_defs"]
    # every code the lenient global setting turns off is on again for these two modules
    assert set(cfg["disable_error_code"]) - {"annotation-unchecked"} <= set(strict[0]["enable_error_code"])
