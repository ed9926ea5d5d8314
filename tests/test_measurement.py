"""`Measurement` (docs/formats.md#measurement): immutable, a JAX pytree whose leaves are the four arrays and whose
metadata is static, equal when its metadata and arrays are."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pytest

from brdffit import Measurement


def small(**changes) -> Measurement:
    wi = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])
    fields = dict(wi=wi, wo=wi[::-1], values=[0.5, 0.25], name="two", extra={"b": 2, "a": 1})
    fields.update(changes)
    return Measurement(**fields)


def test_fields_are_converted_and_checked():
    m = small()
    assert m.values.shape == (2, 1) and m.values.dtype == np.float64  # 1-D values: one channel
    assert np.array_equal(m.weights, [1.0, 1.0]) and m.extra == (("a", 1), ("b", 2))
    with pytest.raises(ValueError, match="complex"):
        small(values=np.array([1 + 1j, 2.0]))
    with pytest.raises(ValueError, match=r"wi \(1, 3\)"):
        small(wi=np.array([[0.0, 0.0, 1.0]]), wo=np.array([[0.0, 0.0, 1.0]]))
    with pytest.raises(ValueError, match=r"weights \(3,\)"):
        small(weights=np.ones(3))


def test_immutable_and_replace_keeps_the_rest():
    m = small()
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.name = "other"
    r = m.replace(name="other")
    assert r.name == "other" and r.extra == m.extra and np.array_equal(r.values, m.values)
    assert dataclasses.replace(m, units="1/sr").name == "two"
    import copy
    import pickle

    assert pickle.loads(pickle.dumps(m)) == m and copy.deepcopy(m) == m  # e.g. to worker processes


def test_equality_compares_metadata_and_array_values():
    assert small() == small()
    assert small() != small(values=[0.5, 0.26])
    assert small() != small(name="three")
    assert small() != small(extra={"a": 1})
    assert small() != small(weights=[1.0, 0.0])
    with pytest.raises(TypeError):
        hash(small())  # holds arrays


def test_a_pytree_of_four_array_leaves_with_static_metadata():
    m = small()
    paths = [jax.tree_util.keystr(p) for p, _ in jax.tree_util.tree_leaves_with_path(m)]
    assert paths == [".wi", ".wo", ".values", ".weights"]
    doubled = jax.tree_util.tree_map(lambda x: 2 * x, m)
    assert isinstance(doubled, Measurement) and doubled.name == "two" and doubled.extra == m.extra
    assert np.array_equal(doubled.values, 2 * np.asarray(m.values))
    # JAX rebuilds the structure with non-array leaves (axis specs, None): no conversion or check
    spec = jax.tree_util.tree_map(lambda x: 0, m)
    assert spec.values == 0 and spec.name == "two"
    traces = []

    @jax.jit
    def total(x: Measurement):
        traces.append(x.name)
        return (x.values[:, 0] * x.weights).sum()

    assert float(total(m)) == 0.75 and float(total(small(values=[1.0, 1.0]))) == 2.0
    assert traces == ["two"]  # same metadata and shapes: one trace
    total(small(name="other"))
    assert traces == ["two", "other"]  # metadata is static
    per_sample = jax.vmap(lambda x: x.values[0] * x.weights, in_axes=(spec,))(m)
    assert np.allclose(per_sample, [0.5, 0.25])
