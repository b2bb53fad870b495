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
    assert main(["mpf", "info", str(tmp_path / "bad.mpf")]) == 1
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


def test_mpf_info_flags_a_lod_over_the_talks_triangle_budget(tmp_path, capsys):
    """A Body3000 of 3,398 triangles (a long strip) is over the ~3,000-triangle LOD budget (10 %
    slack); 3,298 triangles is not; the text never says 'within' a limit it breaks."""
    import numpy as np

    from piste.formats.ssx.mpf import (
        BONE_DTYPE, PALETTE_ENTRY_DTYPE, Group, Link, Mesh, MpfFile, SubModel, pack_chunks, write_mpf,
    )

    def model(n):
        rng = np.random.default_rng(0)
        pos = rng.normal(size=(n, 3)).astype("<f4") * 50
        uv = np.zeros((n, 4), "<i2")
        uv[:, 2], uv[:, 3] = 14, 114
        nrm = np.zeros((n, 3), "<i2")
        bones = np.zeros(1, BONE_DTYPE)
        bones["parent_file"], bones["parent_bone"] = -1, -1
        sub = SubModel(name="Body3000", bones=bones, palettes=[np.array([(100, 0, 0)], PALETTE_ENTRY_DTYPE)],
                       groups=[Group(1, 0, [Link([Mesh(pack_chunks([np.arange(n)], uv, nrm, pos))], np.array([0], "<u4"))])])
        return MpfFile([sub])

    write_mpf(model(3400), tmp_path / "big.mpf")
    write_mpf(model(3300), tmp_path / "ok.mpf")
    capsys.readouterr()
    assert main(["mpf", "info", str(tmp_path / "big.mpf")]) == 0
    out = capsys.readouterr().out
    assert "within the game's limits" not in out and "3,398 triangles" in out and "~3,000-triangle budget" in out
    assert main(["mpf", "info", str(tmp_path / "ok.mpf")]) == 0
    assert "within the game's limits" in capsys.readouterr().out


def test_bench_ssx_mpf_part_runs(capsys, monkeypatch):
    """benchmarks/bench_ssx.py --mpf-only: piste's read + to_model and the benchmark's per-record
    struct reader agree on the encoder's rider pair (the comparison runs before any timing)."""
    import importlib.util
    from pathlib import Path

    monkeypatch.delenv("PISTE_SSX_TRICKY_DIR", raising=False)
    path = Path(__file__).resolve().parents[3] / "benchmarks" / "bench_ssx.py"
    spec = importlib.util.spec_from_file_location("bench_ssx", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.main(["--mpf-only", "--rounds", "1"]) == 0
    out = capsys.readouterr().out
    assert "rider_body.mpf + rider_head.mpf" in out and "outputs equal the peer's" in out and "peer/piste" in out
