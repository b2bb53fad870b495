"""piste mpf: encode, info, copy (byte-identical), export to glTF, errors as one line."""

from __future__ import annotations

import json

from piste.cli import main


def test_mpf_cli_end_to_end(tmp_path, capsys):
    out = tmp_path / "R.mpf"
    assert main(["mpf", "encode", str(out), "--ratios", "1", "0.25", "--report", str(tmp_path / "r.json")]) == 0
    rep = json.loads((tmp_path / "r.json").read_text())
    assert [x["name"] for x in rep["lods"]] == ["Body3000", "Body1500"] and rep["max_chunk_vertices"] <= 55
    capsys.readouterr()
    assert main(["mpf", "info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert [s["name"] for s in info["sub_models"]] == ["Body3000", "Body1500", "BodyShdw750"]
    assert info["sub_models"][2]["groups"] == [17]
    assert info["sub_models"][0]["max_link_matrices"] <= 25 and info["unknown"] == [] and info["game_limits"] == []
    assert info["tag_differences"] == []
    assert main(["mpf", "copy", str(out), str(tmp_path / "C.mpf")]) == 0
    assert (tmp_path / "C.mpf").read_bytes() == out.read_bytes()
    assert main(["mpf", "export", str(out), str(tmp_path / "R.glb")]) == 0
    from piste.formats.gltf import load_gltf

    m = load_gltf(tmp_path / "R.glb")
    assert {"root", "pelvis", "hand_l"} <= set(m.skeleton.names) and set(m.clips) >= {"ride", "spin"}


def test_mpf_cli_bad_file(tmp_path, capsys):
    (tmp_path / "bad.mpf").write_bytes(b"\x0d\0\0\0" + bytes(12))
    assert main(["mpf", "info", str(tmp_path / "bad.mpf")]) == 2
    err = capsys.readouterr().err
    assert "bad.mpf" in err and "format id 13" in err and len(err.strip().splitlines()) == 1


def test_bench_mpf_runs(capsys):
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[3] / "benchmarks" / "bench_mpf.py"
    spec = importlib.util.spec_from_file_location("bench_mpf", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.main(["--quick", "--rounds", "1"]) == 0
    out = capsys.readouterr().out
    assert "3084 / 1542 / 770 triangles in 3 LODs" in out and "read + convert median" in out
