"""How much of a skeleton a clip drives, and the warning when it is too little.

The small part of :mod:`piste.character.retarget` that :meth:`piste.character.Clip.sample` needs on
every foreign-skeleton sample: kept apart so importing the character model (as a bundle render does)
does not import the retargeting machinery (bone-role labelling, bone maps, baking).  ``retarget``
re-exports all three names.

API
---
::

    coverage(clip, target) -> (driven, unmatched)         target joint names
    check_coverage(clip, target, min_fraction=0.5)        warn (RetargetWarning) when fewer than half are driven
"""

from __future__ import annotations

import warnings
from typing import Any

__all__ = ["RetargetWarning", "coverage", "check_coverage"]


class RetargetWarning(UserWarning):
    """A clip drives too few of a skeleton's bones (most of it will stay in its rest pose)."""


def coverage(clip: Any, target: Any) -> tuple[list[str], list[str]]:
    """Target joints the clip drives (by name) and those it does not: ``(driven, unmatched)``."""
    joints = [n for n, j in zip(target.names, target.is_joint) if j] or list(target.names)
    driven = [n for n in joints if n in clip.tracks]
    return driven, [n for n in joints if n not in clip.tracks]


def check_coverage(clip: Any, target: Any, min_fraction: float = 0.5) -> bool:
    """Warn (:class:`RetargetWarning`, naming the unmatched bones) when ``clip`` drives fewer than
    ``min_fraction`` of ``target``'s joints; returns True when coverage is enough."""
    driven, unmatched = coverage(clip, target)
    total = len(driven) + len(unmatched)
    if total == 0 or len(driven) >= min_fraction * total:
        return True
    shown = ", ".join(unmatched[:12]) + (f", ... ({len(unmatched) - 12} more)" if len(unmatched) > 12 else "")
    warnings.warn(f"clip {clip.name!r} drives {len(driven)} of the skeleton's {total} bones; unmatched: {shown} "
                  f"(give a bone map: piste.character.retarget.retarget_clip(clip, skeleton, bone_map='builtin' "
                  f"or {{source: target}}), or a scene file's bone_map)", RetargetWarning, stacklevel=3)
    return False
