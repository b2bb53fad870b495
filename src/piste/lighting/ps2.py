"""The PS2 light-map blend: multiplying by a light map with a blend unit that cannot multiply.

The PS2's Graphics Synthesizer cannot blend ``Cd x Cs``.  Its blend is ``((A - B) x C >> 7) + D``
with ``A, B, D`` each one of ``Cs, Cd, 0`` and ``C`` one of ``As, Ad, FIX``, 8-bit colours and
alpha where ``128 = 1.0`` (the *half-bright* convention; alpha up to 255 ~ 1.99), the result
clamped to 0..255 (COLCLAMP).  The talk's trick draws the light map as a second pass with
``A = Cd, B = Cs, C = As, D = 0``::

    Cd x CL = (Cd - Cs) x As        As = max(CL.r, CL.g, CL.b)        Cs = Cd - Cd x CL / As

``CL`` is the light map, itself half-bright (128 = 1.0).  Because every channel of ``CL`` is at
most ``As``, the real-valued ``Cs = Cd (1 - CL / As)`` lies in ``[0, Cd]``.  What the 8-bit
hardware loses:

* ``Cs`` is an integer and the GS truncates (``>> 7``): the result moves in steps of ``As / 128``
  and cannot round up.  On the brightest channel (``CL = As``) the best it can give is
  ``floor(Cd x As / 128)``; reaching the rounded product there would need ``Cs = -1``: *negative*,
  which the blend cannot take (about half of all pixels lose half a level on that channel).
  The talk's formula rounded to 8 bits (``method="talk"``) is off by up to 2 levels;
* for over-bright light maps (``As > 128``) a step is larger than one level: some results are
  unreachable, at best one level off.  Dark channels under a bright ``As`` (``CL`` channels that
  differ a lot, e.g. a saturated coloured light) get the coarsest steps;
* ``As = 0`` (black light map): any ``Cs`` gives the right answer, 0; we use ``Cs = Cd``;
* ``Cd x CL`` over 255 clamps in both the hardware and true multiplication (they agree).

``method="best"`` raises ``As`` by up to 3 above ``max(CL)`` where that helps, which removes most
of the brightest-channel loss (on uniform random colours: exact 41 % -> 89 % of pixels).

:func:`ps2_source` with ``method="exact"`` (the default) picks, per channel, the ``Cs`` whose GS
result is nearest the true product rounded to 8 bits (:func:`modulate`).  Measured exhaustively
over every (Cd, CL, As) of a channel: the result is always within one level of the rounded true
product; for ``As <= 128`` it is a faithful rounding (the floor or the nearest integer of
``Cd x CL / 128``) and differs from the rounded product only where that rounds up past
``floor(Cd x As / 128)``, the largest value the truncating blend can reach.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from piste.errors import ValidationError

__all__ = ["ps2_source", "ps2_blend", "modulate", "ps2_error_report"]


def _u8(x: npt.ArrayLike, what: str) -> np.ndarray:
    a = np.asarray(x)
    if a.dtype != np.uint8:
        if not np.issubdtype(a.dtype, np.integer) or (a.size and (a.min() < 0 or a.max() > 255)):
            raise ValidationError(f"{what}: expected 8-bit values 0..255 (uint8), got dtype {a.dtype}")
        a = a.astype(np.uint8)
    if a.shape[-1:] != (3,):
        raise ValidationError(f"{what}: expected RGB in the last axis (..., 3), got shape {a.shape}")
    return a


def modulate(cd: npt.ArrayLike, cl: npt.ArrayLike, rounding: str = "nearest") -> np.ndarray:
    """True multiplication of a colour by a half-bright light map in 8 bits: ``Cd x CL / 128``
    rounded to the nearest integer (``rounding="nearest"``, the reference) or truncated
    (``"floor"``: the GS's own MODULATE texture function, ``(Cd x CL) >> 7``), clamped to 255.

    Parameters
    ----------
    cd, cl : (..., 3) uint8

    Returns
    -------
    (..., 3) uint8.
    """
    cd = _u8(cd, "modulate cd").astype(np.int32)
    cl = _u8(cl, "modulate cl").astype(np.int32)
    if rounding == "nearest":
        return np.minimum((cd * cl + 64) >> 7, 255).astype(np.uint8)
    if rounding == "floor":
        return np.minimum((cd * cl) >> 7, 255).astype(np.uint8)
    raise ValidationError(f"modulate: rounding must be 'nearest' or 'floor', got {rounding!r}")


def ps2_blend(cd: npt.ArrayLike, cs: npt.ArrayLike, as_: npt.ArrayLike) -> np.ndarray:
    """What the GS computes for ``(Cd - Cs) x As``: ``((Cd - Cs) * As) >> 7`` clamped to 0..255.

    Parameters
    ----------
    cd, cs : (..., 3) uint8 destination and source colour
    as_ : (...) uint8 source alpha (128 = 1.0)

    Returns
    -------
    (..., 3) uint8.
    """
    cd = _u8(cd, "ps2_blend cd").astype(np.int32)
    cs = _u8(cs, "ps2_blend cs").astype(np.int32)
    a = np.asarray(as_).astype(np.int32)[..., None]
    return np.clip(((cd - cs) * a) >> 7, 0, 255).astype(np.uint8)


def ps2_source(cd: npt.ArrayLike, cl: npt.ArrayLike, method: str = "exact") -> tuple[np.ndarray, np.ndarray]:
    """Source colour and alpha for the second pass, so that ``ps2_blend(cd, cs, as) ~ cd x cl``.

    Parameters
    ----------
    cd : (..., 3) uint8 base colour (the destination after the first pass)
    cl : (..., 3) uint8 half-bright light map (128 = 1.0)
    method : "exact" (``As = max(CL)`` and the ``Cs`` whose GS result is nearest the true
        product, see the module docstring), "talk" (the talk's ``Cs = Cd - round(Cd x CL / As)``)
        or "best" (also lets ``As`` go up to 3 above ``max(CL)``, whichever of the four is nearest
        in total: a larger ``As`` lets the brightest channel round up where ``Cs`` would otherwise
        have to be negative)

    Returns
    -------
    cs (..., 3) uint8, as (...) uint8 (``max(cl.r, cl.g, cl.b)`` except with ``"best"``).
    """
    cd = _u8(cd, "ps2_source cd").astype(np.int64)
    cl = _u8(cl, "ps2_source cl").astype(np.int64)
    m = cl.max(axis=-1)
    if method == "talk":
        safe = np.maximum(m, 1)[..., None]
        d = (2 * cd * cl + safe) // (2 * safe)  # round(cd * cl / as)
        a = m
    elif method == "exact":
        a = m
        d, _ = _best_d(cd, cl, a)
    elif method == "best":
        target = np.minimum((cd * cl + 64) >> 7, 255)
        a, best_err, d = m, None, None
        for k in range(4):
            ak = np.where(m > 0, np.minimum(m + k, 255), 0)
            dk, ek = _best_d(cd, cl, ak, target)
            tot = ek.sum(axis=-1)
            if best_err is None:
                a, d, best_err = ak, dk, tot
            else:
                better = tot < best_err
                a = np.where(better, ak, a)
                d = np.where(better[..., None], dk, d)
                best_err = np.minimum(tot, best_err)
    else:
        raise ValidationError(f"ps2_source: method must be 'exact', 'best' or 'talk', got {method!r}")
    d = np.clip(d, 0, cd)
    d = np.where(a[..., None] == 0, 0, d)  # black light map: any Cs works; Cs = Cd
    cs = (cd - d).astype(np.uint8)
    return cs, a.astype(np.uint8)


def _best_d(cd: np.ndarray, cl: np.ndarray, a: npt.ArrayLike,
            target: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per channel, the ``d = Cd - Cs`` in ``[0, Cd]`` whose GS result ``(d a) >> 7`` is nearest
    the rounded product; returns ``(d, abs error)``, int64 arrays like ``cd``."""
    if target is None:
        target = np.minimum((cd * cl + 64) >> 7, 255)
    a3 = np.asarray(a)[..., None]
    safe = np.maximum(a3, 1)
    hi = np.clip((target * 128 + safe - 1) // safe, 0, cd)  # smallest d reaching the target
    lo = np.maximum(hi - 1, 0)
    err_hi = np.abs(np.minimum((hi * a3) >> 7, 255) - target)
    err_lo = np.abs(np.minimum((lo * a3) >> 7, 255) - target)
    use_lo = err_lo < err_hi
    return np.where(use_lo, lo, hi), np.where(use_lo, err_lo, err_hi)


def ps2_error_report(base: npt.ArrayLike, lightmap: npt.ArrayLike, method: str = "exact") -> dict[str, Any]:
    """How far the PS2 trick is from true multiplication over a whole scene.

    Parameters
    ----------
    base : (..., 3) uint8 base colours Cd (e.g. every pixel of a frame, or every texel pairing)
    lightmap : (..., 3) uint8 half-bright light-map colours CL at the same places
    method : as in :func:`ps2_source`

    Returns
    -------
    dict with ``pixels``, ``method``, per channel ``mean_abs`` and ``max_abs`` (8-bit levels),
    ``exact_fraction``, ``overbright_fraction`` (As > 128), ``clamped_fraction`` (true product
    over 255), ``cs_negative_needed`` (pixels where, with ``As = max(CL)``, hitting the rounded
    product on some channel would need ``Cs < 0``: the brightest channel rounding up; the real
    valued ``Cs`` is never negative), ``by_alpha`` (mean / max error for As in 0, 1..64, 65..128, 129..192, 193..255),
    ``by_spread`` (the same against max - min of the CL channels: 0..15, 16..63, 64..127, 128..255)
    and ``worst`` (up to 5 ``{cd, cl, ps2, true}`` examples of the largest error).
    """
    cd = _u8(base, "ps2_error_report base").reshape(-1, 3)
    cl = _u8(lightmap, "ps2_error_report lightmap").reshape(-1, 3)
    if cd.shape != cl.shape:
        raise ValidationError(f"ps2_error_report: base {cd.shape} and lightmap {cl.shape} differ in shape")
    cs, a = ps2_source(cd, cl, method)
    got = ps2_blend(cd, cs, a).astype(np.int32)
    true = modulate(cd, cl).astype(np.int32)
    err = np.abs(got - true)  # (k, 3)
    k = len(cd)
    # with As = max(CL): the d = Cd - Cs that would reach the rounded product exactly
    m = np.maximum(cl.max(1).astype(np.int64), 1)[:, None]
    need_d = (true.astype(np.int64) * 128 + m - 1) // m
    need_negative = ((need_d > cd) & (cl.max(1) > 0)[:, None]).any(axis=1)
    per_px = err.max(axis=1)

    def summary(mask: np.ndarray) -> dict:
        if not mask.any():
            return {"pixels": 0, "mean_abs": 0.0, "max_abs": 0}
        e = err[mask]
        return {"pixels": int(mask.sum()), "mean_abs": float(e.mean()), "max_abs": int(e.max())}

    ai = a.astype(np.int32)
    spread = cl.max(1).astype(np.int32) - cl.min(1).astype(np.int32)
    by_alpha = {
        name: summary((ai >= lo) & (ai <= hi))
        for name, lo, hi in (("0", 0, 0), ("1-64", 1, 64), ("65-128", 65, 128), ("129-192", 129, 192), ("193-255", 193, 255))
    }
    by_spread = {
        name: summary((spread >= lo) & (spread <= hi))
        for name, lo, hi in (("0-15", 0, 15), ("16-63", 16, 63), ("64-127", 64, 127), ("128-255", 128, 255))
    }
    worst_idx = np.argsort(-per_px, kind="stable")[: min(5, k)]
    worst = [
        {"cd": cd[i].tolist(), "cl": cl[i].tolist(), "ps2": got[i].tolist(), "true": true[i].tolist()}
        for i in worst_idx
        if per_px[i] > 0
    ]
    return {
        "method": method,
        "pixels": int(k),
        "mean_abs": err.mean(axis=0).tolist() if k else [0.0, 0.0, 0.0],
        "max_abs": err.max(axis=0).tolist() if k else [0, 0, 0],
        "exact_fraction": float((per_px == 0).mean()) if k else 1.0,
        "overbright_fraction": float((ai > 128).mean()) if k else 0.0,
        "clamped_fraction": float(((cd.astype(np.int32) * cl + 64) >> 7 > 255).any(axis=1).mean()) if k else 0.0,
        "cs_negative_needed": int(need_negative.sum()),
        "by_alpha": by_alpha,
        "by_spread": by_spread,
        "worst": worst,
    }
