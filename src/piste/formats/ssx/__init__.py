"""SSX Tricky (PS2) level files: patches (``.pbd``), texture banks (``.ssh``), light-map pages
(``_L.ssh``), the modding community's Multitool project, and piste's own synthetic-level encoder.

Facts: ``/work/shared/SSX-FORMATS.md`` (public community documentation; no code copied).

pbd        read_pbd / write_pbd / Pbd (per-patch arrays, byte-identical round trip, to_net)
ssh        read_ssh / write_ssh / SshBank / SshImage; light-map pages and tiles
lightmap   the game's Cs / As texels against 8x8-reduced base textures (pure numpy)
synth      make_level: synthetic levels (the tests' golden files)
afl        read_afl / write_afl / encode_afl / afl_clips: rider animation banks (.afl) as piste clips
"""

from piste.formats.ssx.pbd import (
    GAME_SCALE, PATCH_DTYPE, Pbd, bezier_to_power, default_lightmap_tiles, parse_pbd, power_to_bezier, read_pbd,
    records_from_arrays, records_from_net, write_pbd,
)
from piste.formats.ssx.ssh import (
    SshBank, SshImage, extract_tiles, lightmap_bank, lightmap_pages, parse_ssh, place_tiles, read_ssh, write_ssh,
)
from piste.formats.ssx.lightmap import base_tiles, gs_blend, light_from_source, reduce_texture
from piste.formats.ssx.synth import SynthLevel, make_level

__all__ = [
    "Pbd", "read_pbd", "parse_pbd", "write_pbd", "PATCH_DTYPE", "GAME_SCALE", "bezier_to_power", "power_to_bezier",
    "records_from_arrays", "records_from_net", "default_lightmap_tiles",
    "SshBank", "SshImage", "read_ssh", "parse_ssh", "write_ssh", "lightmap_pages", "lightmap_bank", "extract_tiles",
    "place_tiles",
    "reduce_texture", "base_tiles", "gs_blend", "light_from_source",
    "make_level", "SynthLevel",
]
from piste.formats.ssx.mpf import MpfFile, SubModel, mpf_bytes, parse_mpf, read_mpf, write_mpf  # noqa: E402
from piste.formats.ssx.mpf_model import SsxModel, mpf_to_model  # noqa: E402
from piste.formats.ssx.mpf_encode import model_to_mpf  # noqa: E402
__all__ += ["MpfFile", "SubModel", "read_mpf", "parse_mpf", "write_mpf", "mpf_bytes",  # SSX Tricky models (.mpf)
            "SsxModel", "mpf_to_model", "model_to_mpf"]
from piste.formats.ssx.afl import (  # noqa: E402
    AflClipData, AflFile, afl_bytes, afl_clips, encode_afl, mpf_body_bones, parse_afl, read_afl, write_afl,
)
__all__ += ["AflFile", "AflClipData", "read_afl", "parse_afl", "write_afl", "afl_bytes",  # rider animation banks (.afl)
            "encode_afl", "afl_clips", "mpf_body_bones"]
