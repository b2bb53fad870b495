"""``piste mpf``: SSX Tricky rider models (.mpf).

  piste mpf info RIDER.mpf                      sub-models, bones, palettes, chunks, unknown bytes
  piste mpf encode OUT.mpf [--model M.glb]      a piste rider (default: the built-in one) as an .mpf,
                                                and its texture as OUT.ssh (8-bit indexed; --no-texture:
                                                none), with the quantisation report (--report R.json);
                                                --split-head: OUT_body.mpf + OUT_head.mpf (head bones
                                                in file id 2, parented onto body bones by file id)
  piste mpf export RIDER.mpf OUT.glb            the decoded rider (+ shared clips) as glTF;
                                                --clips BANK.afl: the game's own clips instead
  piste mpf copy RIDER.mpf OUT.mpf              read and write back (byte-identical when unedited)
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from piste.errors import ConfigError

if TYPE_CHECKING:
    import argparse

    from piste.formats.ssx.mpf import MpfFile


def add_arguments(p: argparse.ArgumentParser) -> None:
    from piste.commands import _numbers as N

    sub = p.add_subparsers(dest="mpf_command", metavar="ACTION")
    sub.required = True
    a = sub.add_parser("info", help="list the sub-models, bones, palettes, chunks and unknown bytes")
    a.add_argument("file", help="an .mpf model file")
    a.add_argument("--json", action="store_true", help="print JSON")
    e = sub.add_parser("encode", help="write a piste rider as an SSX Tricky .mpf")
    e.add_argument("out", help="output .mpf")
    e.add_argument("--model", default="builtin:rider", help="builtin:rider (default) or a skinned .gltf/.glb")
    e.add_argument("--ratios", type=N.real(0.0, 1.0, lo_open=True), nargs="+", default=[1.0, 0.5, 0.25],
                   help="triangle ratio of each LOD (Body3000, Body1500, Body750; default 1 0.5 0.25)")
    e.add_argument("--report", help="also write the quantisation report as JSON here")
    e.add_argument("--split-head", action="store_true",
                   help="write the game's pair OUT_body.mpf + OUT_head.mpf (the head bone's subtree and the "
                        "head's triangles in the head file, file id 2)")
    e.add_argument("--head-bone", help="with --split-head: the bone whose subtree is the head file (default: the head)")
    e.add_argument("--no-texture", action="store_true",
                   help="do not write the rider's texture as OUT.ssh (an 8-bit indexed SSX texture bank)")
    x = sub.add_parser("export", help="export the decoded rider with the shared clips to glTF")
    x.add_argument("file", help="an .mpf (a _body.mpf reads its _head.mpf partner too)")
    x.add_argument("out", help="output .glb or .gltf")
    x.add_argument("--texture", action="append",
                   help="an .ssh texture bank (repeatable; default: the .ssh with the model's stem beside it)")
    x.add_argument("--clips", action="append", metavar="BANK.afl",
                   help="an SSX Tricky .afl animation bank (repeatable): export its clips (body tracks) instead of "
                        "piste's shared clips")
    x.add_argument("--fps", type=N.real(1.0, 240.0), default=30.0,
                   help="with --clips: AFL frames a second (default 30; the public notes' assumption, not confirmed)")
    c = sub.add_parser("copy", help="read and write back (byte-identical when nothing changed)")
    c.add_argument("file")
    c.add_argument("out")


def _info(f: MpfFile, *partners: MpfFile) -> dict[str, Any]:
    from piste.formats.ssx.mpf import game_limits, tag_differences

    out: dict[str, Any] = {"file": f.path, "format_id": f.format_id, "sub_models": [], "unknown": [list(u) for u in f.unknown],
           "partners": [p.path for p in partners], "game_limits": [list(x) for x in game_limits(f, *partners)],
           "tag_differences": [list(x) for x in tag_differences(f)]}
    for s in f.models:
        chunks = [c for lk in s.links for m in lk.meshes for c in m.chunks]
        out["sub_models"].append({
            "name": s.name, "file_id": s.file_id, "bones": len(s.bones), "materials": len(s.materials),
            "ik_points": len(s.ik), "groups": [g.type for g in s.groups], "links": len(s.links),
            "palettes": len(s.palettes), "morph_keys": s.morph_keys, "chunks": len(chunks),
            "vertices": int(sum(c.n_vertices for c in chunks)), "triangles": s.n_triangles,
            "max_chunk_vertices": int(max((c.n_vertices for c in chunks), default=0)),
            "max_link_matrices": int(max((len(lk.refs) for lk in s.links), default=0))})
    return out


def run(args: argparse.Namespace) -> int:
    from piste.formats.ssx.mpf import read_mpf, write_mpf

    if args.mpf_command == "info":
        from piste.formats.ssx.mpf_model import mpf_partners

        head, _ = mpf_partners(args.file)  # a _body.mpf's LOD budgets count its _head.mpf's triangles too
        info = _info(read_mpf(args.file), *([read_mpf(head)] if head is not None else []))
        if args.json:
            print(json.dumps(info, indent=1))
            return 0
        print(f"{args.file}: format id {info['format_id']}, {len(info['sub_models'])} sub-models")
        for s in info["sub_models"]:
            print(f"  {s['name']:<16} file {s['file_id']:>3}  bones {s['bones']:>3}  palettes {s['palettes']:>4}  "
                  f"groups {s['groups']}  links {s['links']:>3}  chunks {s['chunks']:>4}  vertices {s['vertices']:>5}  "
                  f"triangles {s['triangles']:>5}  morph keys {s['morph_keys']}")
        for w, o, n, note in info["unknown"]:
            print(f"  unknown: {w} @ {o} ({n} bytes): {note}")
        for w, n, total, nb in info["tag_differences"]:
            print(f"  {w}: {n} of {total} chunks carry tag bytes piste's layout would write differently "
                  f"({nb} bytes; kept as read unless the blob is laid out anew)")
        for w, problem in info["game_limits"]:
            print(f"  over the game's limits: {w}: {problem}")
        if info["partners"]:
            print(f"  LOD triangle budgets counted with {', '.join(info['partners'])}")
        if not info["game_limits"]:
            print("  within the game's limits (<= 59 vertices a chunk, <= 165 a shadow chunk, <= 25 palettes a link, "
                  "25 % weight steps, ~3,000 / 1,500 / 750 triangles a LOD)")
        return 0
    if args.mpf_command == "encode":
        from piste.formats.ssx.mpf_encode import model_to_mpf
        from piste.pipeline.sources import load_rider_model

        if len(args.ratios) > 3:
            raise ConfigError("at most three LODs (Body3000, Body1500, Body750)")
        model = load_rider_model(args.model)
        out = Path(args.out)
        if args.split_head:
            from piste.formats.ssx.mpf_encode import model_to_mpf_pair

            f, head, report = model_to_mpf_pair(model, head_bone=args.head_bone, ratios=tuple(args.ratios))
            base = out.stem[:-5] if out.stem.lower().endswith("_body") else out.stem
            out = out.with_name(base + "_body" + out.suffix)
            head_out = out.with_name(base + "_head" + out.suffix)
        elif args.head_bone:
            raise ConfigError("--head-bone needs --split-head")
        else:
            f, report = model_to_mpf(model, ratios=tuple(args.ratios))
        bank = None
        if not args.no_texture:
            from piste.formats.ssx.mpf_encode import texture_bank

            bank, report["texture"] = texture_bank(model)
        write_mpf(f, out)
        if args.split_head:
            write_mpf(head, head_out)
            sp = report["split"]
            print(f"wrote {head_out}: head bones {', '.join(sp['head_bones'])}; head / body triangles "
                  + ", ".join(f"{x['head']} / {x['body']}" for x in sp["lods"]))
        if bank is not None:
            from piste.formats.ssx.ssh import write_ssh

            ssh = out.with_suffix(".ssh")
            write_ssh(bank, ssh)
            t = report["texture"]
            print(f"wrote {ssh}: {t['name']!r} {t['size'][0]}x{t['size'][1]} 8-bit, {t['colours']} colours, "
                  f"mean error {t['mean_error']:.2f} / max {t['max_error']} levels" + (f" ({t['note']})" if t["note"] else ""))
        if args.report:
            from piste.formats.atomic import write_bytes_atomic

            write_bytes_atomic(args.report, json.dumps(report, indent=1).encode())
        print(f"wrote {out}: " + ", ".join(f"{x['name']} {x['triangles']} triangles / {x['palette']} palettes / "
                                                f"{x['chunks']} chunks" for x in report["lods"]))
        print(f"weights in {int(report['step'] * 100)} % steps: {report['weights_changed']} vertices changed, max "
              f"weight error {report['max_weight_error']:.3f}; max position error {report['max_bind_error_m'] * 1000:.4f} mm "
              f"(bind), {report['max_pose_error_m'] * 1000:.1f} mm ({report['pose']})")
        return 0
    if args.mpf_command == "export":
        from piste.formats.gltf.write import CharacterExport, export_gltf
        from piste.pipeline.ssx_rider import load_mpf_rider

        model = load_mpf_rider(args.file, texture=args.texture)
        if args.clips:
            from piste.formats.ssx.afl import read_afl
            from piste.pipeline.ssx_rider import afl_rider_clips

            clips = {}
            for bank in args.clips:
                afl = read_afl(bank)
                for n, c in afl_rider_clips(model, afl, fps=args.fps).items():
                    key = n if n not in clips else f"{Path(bank).stem}/{n}"
                    c.name = key
                    clips[key] = c
                for note in afl.notes:
                    print(f"  note: {bank}: {note}")
            if not clips:
                raise ConfigError(f"{', '.join(args.clips)}: no clip with a body track to export")
            driven = {b for c in clips.values() for b in c.tracks}
            print(f"{len(clips)} clips from {', '.join(args.clips)}: {len(driven)} of the model's "
                  f"{model.skeleton.n_bones} bones driven")
            model.clips = clips
        r = export_gltf(args.out, characters=[CharacterExport(model, name=model.name)])
        print(f"wrote {r.path} ({r.bytes} bytes, {r.animations} animations)")
        return 0
    if args.mpf_command == "copy":
        notes = write_mpf(read_mpf(args.file), args.out)
        same = Path(args.file).read_bytes() == Path(args.out).read_bytes()
        print(f"wrote {args.out} ({'byte-identical' if same else 'changed'})")
        for n in notes:
            print(f"  note: {n}")
        return 0
    raise ConfigError(f"unknown action {args.mpf_command!r}")
