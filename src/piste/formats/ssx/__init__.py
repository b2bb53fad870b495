"""SSX Tricky (PS2) level files: patches (``.pbd``), texture banks (``.ssh``), light-map pages
(``_L.ssh``), the modding community's Multitool project, and piste's own synthetic-level encoder.

Facts: ``/work/shared/SSX-FORMATS.md`` (public community documentation; no code copied).

pbd        read_pbd / write_pbd / Pbd (per-patch arrays, byte-identical round trip; as a PatchNet: piste.pipeline.ssx_level.pbd_to_net)
ssh        read_ssh / write_ssh / SshBank / SshImage; light-map pages and tiles
lightmap   the game's Cs / As texels against 8x8-reduced base textures (pure numpy)
synth      pbd_bytes, synthetic_textures: the bytes of a whole .pbd (synthetic levels: piste.pipeline.ssx_synth)
afl        read_afl / write_afl / encode_afl / afl_clips: rider animation banks (.afl) as piste clips
"""

from typing import TYPE_CHECKING

from piste import _lazy_exports

# every name is imported when first asked for (PEP 562; tests/test_lazy_imports.py)
__all__, __getattr__, __dir__ = _lazy_exports(__name__, {
    "pbd": ("Pbd", "read_pbd", "parse_pbd", "write_pbd", "PATCH_DTYPE", "GAME_SCALE", "bezier_to_power",
            "power_to_bezier", "records_from_arrays", "records_from_net", "default_lightmap_tiles"),
    "ssh": ("SshBank", "SshImage", "read_ssh", "parse_ssh", "write_ssh", "lightmap_pages", "lightmap_bank",
            "extract_tiles", "place_tiles"),
    "lightmap": ("reduce_texture", "base_tiles", "gs_blend", "light_from_source"),
    "mpf": ("MpfFile", "SubModel", "read_mpf", "parse_mpf", "write_mpf", "mpf_bytes"),  # SSX Tricky models (.mpf)
    "mpf_model": ("SsxModel", "mpf_to_model"),
    "mpf_encode": ("model_to_mpf",),
    "afl": ("AflFile", "AflClipData", "read_afl", "parse_afl", "write_afl", "afl_bytes", "encode_afl", "afl_clips",
            "mpf_body_bones"),  # rider animation banks (.afl)
})

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and the import graph
    from piste.formats.ssx.pbd import GAME_SCALE, PATCH_DTYPE, Pbd, bezier_to_power, default_lightmap_tiles, parse_pbd, power_to_bezier, read_pbd, records_from_arrays, records_from_net, write_pbd  # noqa: F401
    from piste.formats.ssx.ssh import SshBank, SshImage, extract_tiles, lightmap_bank, lightmap_pages, parse_ssh, place_tiles, read_ssh, write_ssh  # noqa: F401
    from piste.formats.ssx.lightmap import base_tiles, gs_blend, light_from_source, reduce_texture  # noqa: F401
    from piste.formats.ssx.mpf import MpfFile, SubModel, mpf_bytes, parse_mpf, read_mpf, write_mpf  # noqa: F401
    from piste.formats.ssx.mpf_model import SsxModel, mpf_to_model  # noqa: F401
    from piste.formats.ssx.mpf_encode import model_to_mpf  # noqa: F401
    from piste.formats.ssx.afl import AflClipData, AflFile, afl_bytes, afl_clips, encode_afl, mpf_body_bones, parse_afl, read_afl, write_afl  # noqa: F401
