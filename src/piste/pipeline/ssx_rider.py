"""SSX Tricky riders in scenes: a scene's ``model = "ssx:RIDER.mpf"`` becomes a playable rider.

The ``.mpf`` holds the body (and a ``<name>_head.mpf`` beside a ``<name>_body.mpf`` is read with
it: head bones parent onto body bones across the two files); animation clips are not in model
files, so the rider plays piste's shared clips (the default rider's ``ride``, ``crouch``, ``grab``,
``spin``), matched to the model's bones **by name** (:class:`piste.character.Clip`'s retarget
rule). A model built by piste's encoder from the default rider has the same bone names and plays
them exactly; a retail model's bones (``hips``, ``l_clav``, ``l_thigh``, ``r_calf``, ...) are
matched by role through the built-in bone map of :mod:`piste.character.retarget` (``notes`` says
how many); a model none of whose bones can be matched stands in its bind pose (``notes`` says so).

The LODs the character build step uses are the file's own (``Body3000`` / ``1500`` / ``750``,
each with its own weight palettes) when the scene asks for three levels.

API
---
load_mpf_rider(path) -> piste.formats.ssx.SsxModel (with clips)
shared_clips(model) -> dict of the default rider's clips, and how many bones they drive
"""

from __future__ import annotations

from pathlib import Path

from piste.character.retarget import builtin_bone_map, retarget_clip
from piste.character.rider import default_rider
from piste.errors import ConfigError
from piste.formats.ssx.mpf import read_mpf
from piste.formats.ssx.mpf_model import mpf_to_model

__all__ = ["load_mpf_rider", "shared_clips"]


def shared_clips(model) -> tuple:
    """The default rider's clips for ``model`` and the number of ``model``'s bones they animate.

    When every bone the clips animate has its name in ``model`` they play as they are; otherwise
    (a retail rider's ``hips``, ``l_thigh``, ``r_calf``, ...) they are retargeted through the
    built-in bone map (:func:`piste.character.retarget.builtin_bone_map`: roles from the names,
    or from the hierarchy), and ``model.notes`` says how many bones that mapped."""
    src = default_rider(0)
    sk = model.skeleton
    names = set(sk.names)
    animated = {b for c in src.clips.values() for b in c.tracks}
    if animated <= names:
        return dict(src.clips), len(animated)
    bone_map = builtin_bone_map(src.skeleton, sk)
    clips = {n: retarget_clip(c, sk, bone_map, source=src.skeleton, warn=False) for n, c in src.clips.items()}
    driven = {b for c in clips.values() for b in c.tracks}
    by_role = [f"{k} -> {v}" for k, v in bone_map.items() if k != v and k in animated]
    notes = getattr(model, "notes", None)
    if driven and notes is not None:
        notes.append(f"shared clips retargeted by the built-in bone map: {len(driven)} of the model's {sk.n_bones} "
                     f"bones driven, {len(by_role)} matched by role ({', '.join(by_role[:4])}, ...)")
    return clips, len(driven)


def load_mpf_rider(path) -> object:
    """Read an ``.mpf`` rider (plus its ``_head.mpf`` partner when ``path`` is a ``_body.mpf``),
    convert it and give it the shared clips."""
    path = Path(path)
    files = [read_mpf(path)]
    stem = path.stem
    if stem.lower().endswith("_body"):
        head = path.with_name(stem[:-5] + ("_HEAD" if stem.endswith("_BODY") else "_head") + path.suffix)
        if head.is_file():
            files.append(read_mpf(head))
    model = mpf_to_model(*files, name=stem)
    if not model.meshes:
        raise ConfigError(f"{path}: no render sub-models to draw")
    model.clips, driven = shared_clips(model)
    if driven == 0:
        model.notes.append("none of the shared clips' bones are in this model: it stands in its bind pose")
    return model
