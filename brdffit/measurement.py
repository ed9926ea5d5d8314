"""`Measurement`: the one in-memory form of every reflectance source (docs/formats.md#measurement).

Samples are (wi, wo) pairs in the local shading frame (docs/conventions.md#conventions) with a BRDF value per channel,
in 1/sr, without the cosine foreshortening. ``weights`` 0 marks an invalid sample (kept so that
a UBO table keeps its 81 x 81 shape).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np

from . import _x64  # noqa: F401 - float64 before any JAX work (brdffit/_x64.py)
from .grid import UBO_SIZE

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Array, Float


def _as_float_array(x) -> Array:
    if np.iscomplexobj(x):  # casting would drop the imaginary part with only a warning
        raise ValueError("a Measurement holds real numbers, not complex values")
    return jnp.asarray(x, dtype=jnp.result_type(float))


def _unit_rows(w) -> Array:
    """Directions as unit vectors (docs/conventions.md#conventions): a row whose length is off 1 by more than 1e-6 (float32 round-off is 6e-8) is
    normalised (docs/fitting.md#hostile-but-valid-data: non-unit directions went into the formulas as they were and biased the
    fit, alpha 0.105 for 0.2). Rows of length 0 or not finite are kept: they are invalid samples,
    and a fit leaves them out where they lie below the horizon or carry weight 0."""
    if np.iscomplexobj(w):
        raise ValueError("a Measurement holds real numbers, not complex values")
    a = np.asarray(w, dtype=np.float64)
    if a.ndim == 2 and a.shape[-1] == 3:
        norm = np.sqrt(np.einsum("ij,ij->i", a, a))
        off = np.isfinite(norm) & (norm > 0) & (np.abs(norm - 1.0) > 1e-6)
        if off.any():
            a = a.copy()
            a[off] /= norm[off, None]
            return _as_float_array(a)
    return _as_float_array(w)


def _freeze(extra) -> tuple[tuple[str, Any], ...]:
    if extra is None:
        return ()
    items = extra.items() if isinstance(extra, dict) else extra
    return tuple(sorted((str(k), v) for k, v in items))


_ARRAYS = ("wi", "wo", "values", "weights")
_METADATA = ("name", "source", "grid", "colour_space", "units", "extra")


# A frozen dataclass registered as a pytree by hand rather than an equinox Module: equinox's
# import (~0.2 s) was the largest part of `brdffit fit`'s imports after JAX's that the command
# does not otherwise need (optimistix, and so equinox, load only when a fit is compiled).
@dataclasses.dataclass(frozen=True, init=False, eq=False, repr=False)
class Measurement:
    """Tabulated or scattered BRDF samples.

    ``Measurement(wi=..., wo=..., values=...)`` with optional ``weights`` (default 1) and metadata.
    It is immutable and a JAX pytree: the arrays are leaves, the metadata is static.
    """

    wi: Float[Array, "N 3"]
    wo: Float[Array, "N 3"]
    values: Float[Array, "N C"]
    weights: Float[Array, " N"]
    name: str
    source: str
    grid: str | None
    colour_space: str
    units: str
    #: Further metadata as sorted (key, value) pairs, e.g. the reader's options; see ``.meta``.
    extra: tuple[tuple[str, Any], ...]

    def __init__(
        self,
        wi,
        wo,
        values,
        weights=None,
        *,
        name: str = "measurement",
        source: str = "",
        grid: str | None = None,
        colour_space: str = "linear_rec709",
        units: str = "1/sr",
        extra=None,
    ):
        values = _as_float_array(values)
        if values.ndim == 1:
            values = values[:, None]
        fields = {
            "wi": _unit_rows(wi), "wo": _unit_rows(wo), "values": values,
            "weights": _as_float_array(jnp.ones(values.shape[0]) if weights is None else weights),
            "name": name, "source": source, "grid": grid, "colour_space": colour_space, "units": units,
            "extra": _freeze(extra),
        }
        for key, value in fields.items():
            object.__setattr__(self, key, value)
        n = self.values.shape[0]
        if self.wi.shape != (n, 3) or self.wo.shape != (n, 3):
            raise ValueError(
                f"wi {self.wi.shape} and wo {self.wo.shape} must be ({n}, 3) to match values {self.values.shape}"
            )
        if self.weights.shape != (n,):
            raise ValueError(f"weights {self.weights.shape} must be ({n},)")
        if self.grid == "ubo81" and n != UBO_SIZE * UBO_SIZE:
            raise ValueError(f"a ubo81 measurement has {UBO_SIZE * UBO_SIZE} samples, not {n}")

    def __eq__(self, other: object) -> bool:
        """Same metadata and the same array values (shapes included)."""
        if type(other) is not type(self):
            return NotImplemented
        return all(getattr(self, k) == getattr(other, k) for k in _METADATA) and all(
            np.array_equal(np.asarray(getattr(self, k)), np.asarray(getattr(other, k))) for k in _ARRAYS
        )

    __hash__ = None  # holds arrays

    # -- convenience -----------------------------------------------------------------------------
    @property
    def n_samples(self) -> int:
        return int(self.values.shape[0])

    @property
    def n_channels(self) -> int:
        return int(self.values.shape[1])

    @property
    def meta(self) -> dict[str, Any]:
        """All metadata as one dict (the named fields plus ``extra``)."""
        return {
            "name": self.name,
            "source": self.source,
            "grid": self.grid,
            "colour_space": self.colour_space,
            "units": self.units,
            **dict(self.extra),
        }

    def valid_mask(self) -> np.ndarray:
        """Samples a fit may use: weight > 0, finite values, both directions above the horizon."""
        values = np.asarray(self.values)
        return (
            (np.asarray(self.weights) > 0)
            & np.all(np.isfinite(values), axis=1)
            & (np.asarray(self.wi)[:, 2] > 0)
            & (np.asarray(self.wo)[:, 2] > 0)
        )

    def table(self) -> Float[np.ndarray, "81 81 C"]:
        """The (light, view, channel) table of a UBO-81 measurement."""
        if self.grid != "ubo81":
            raise ValueError(f"{self.name}: .table() needs a ubo81 measurement, this one has grid={self.grid!r}")
        return np.asarray(self.values).reshape(UBO_SIZE, UBO_SIZE, self.n_channels)

    def replace(self, **changes) -> "Measurement":
        """A copy with some fields changed."""
        fields = {k: getattr(self, k) for k in _ARRAYS + _METADATA}
        fields["extra"] = dict(self.extra)
        fields.update(changes)
        return Measurement(**fields)

    def __repr__(self) -> str:
        return (
            f"Measurement(name={self.name!r}, samples={self.n_samples}, channels={self.n_channels}, "
            f"grid={self.grid!r}, source={self.source!r})"
        )


def _flatten(m: Measurement):
    return tuple(getattr(m, k) for k in _ARRAYS), tuple(getattr(m, k) for k in _METADATA)


def _flatten_with_keys(m: Measurement):
    arrays, metadata = _flatten(m)
    return tuple(zip((jax.tree_util.GetAttrKey(k) for k in _ARRAYS), arrays)), metadata


def _unflatten(metadata, arrays) -> Measurement:
    # As JAX rebuilds it inside transformations: leaves may be tracers, None or axis numbers, so
    # neither the conversion nor the shape checks of __init__ apply.
    m = object.__new__(Measurement)
    for key, value in zip(_ARRAYS + _METADATA, (*arrays, *metadata)):
        object.__setattr__(m, key, value)
    return m


jax.tree_util.register_pytree_with_keys(Measurement, _flatten_with_keys, _unflatten, _flatten)
