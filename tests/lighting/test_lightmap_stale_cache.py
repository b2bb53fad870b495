import json

import numpy as np
import pytest

from piste.errors import FormatError
from piste.lighting.baker import MANIFEST_FORMAT, load_lightmap


def test_unreadable_cache_entry_is_a_format_error(tmp_path):
    """An entry in an old layout (non-scalar 'res') must read as stale, not crash the caller."""
    (tmp_path / "manifest.json").write_text(json.dumps({"format": MANIFEST_FORMAT}))
    np.savez(tmp_path / "lightmap.npz", atlas=np.zeros((2, 2, 3)), rects=np.zeros((1, 4)),
             res=np.array([8, 8]), gutter=np.array(1))
    with pytest.raises(FormatError, match="field 'files': expected the SHA-256 sums"):
        load_lightmap(tmp_path)  # no sums: refused before reading
    with pytest.raises(FormatError, match="unreadable light map"):
        load_lightmap(tmp_path, verify=False)
    (tmp_path / "lightmap.npz").write_bytes(b"truncated")
    with pytest.raises(FormatError, match="lightmap.npz"):
        load_lightmap(tmp_path, verify=False)
