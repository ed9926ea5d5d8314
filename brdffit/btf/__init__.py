"""Per-texel fitting of UBO BTFs (docs/btf.md#btfs-per-texel-fitting): read (:func:`load_btf`), fit (:func:`fit_btf` ->
:class:`ParameterMaps`; here, on ``jax.distributed`` processes or a Dask cluster), fit a folder of
BTFs (:func:`fit_btf_database`), validate against the BTF's own photographs (:func:`validate_btf`),
and generated test BTFs (:mod:`brdffit.btf.generate`)."""

from __future__ import annotations

import importlib

from .. import _x64  # noqa: F401 - float64 before any JAX work (brdffit/_x64.py)

_LAZY = {
    "BTF": "brdffit.btf.reader",
    "load_btf": "brdffit.btf.reader",
    "ParameterMaps": "brdffit.btf.maps",
    "fit_btf": "brdffit.btf.fit",
    "fit_btf_database": "brdffit.btf.database",
    "DatabaseFit": "brdffit.btf.database",
    "validate_btf": "brdffit.btf.validate",
    "BTFValidation": "brdffit.btf.validate",
}


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'brdffit.btf' has no attribute {name!r}")


__all__ = list(_LAZY)
