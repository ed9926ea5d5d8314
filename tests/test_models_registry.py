"""docs/models.md#how-models-are-tested: the registry, docs/models.md#models names, composition naming, declared linearity, solver transform."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from brdffit.models import get, names

# docs/models.md#models, normative: name -> ((parameter, channels), ...)
LIBRARY_MODELS = {
    "lambert": (("kd", 3),),
    "phong": (("kd", 3), ("ks", 3), ("n", 1)),
    "phong_classic": (("kd", 3), ("ks", 3), ("n", 1)),
    "blinn_phong": (("kd", 3), ("ks", 3), ("n", 1)),
    "ward": (("kd", 3), ("ks", 3), ("alpha_x", 1), ("alpha_y", 1)),
    "torrance_sparrow": (("kd", 3), ("ks", 3), ("m", 1), ("f0", 1)),
    "cook_torrance": (("kd", 3), ("ks", 3), ("alpha", 1), ("f0", 1)),
    "ggx": (("kd", 3), ("ks", 3), ("alpha", 1), ("f0", 1)),
    "oren_nayar": (("kd", 3), ("sigma", 1)),
    "lafortune": (("kd", 3), ("rho", 3), ("cx", 1), ("cz", 1), ("n", 1)),
    "ashikhmin_shirley": (("rd", 3), ("rs", 3), ("nu", 1), ("nv", 1)),
}


# docs/materials.md#native-materials-and-exports: the native models (a renderer's or format's own BSDF); their parameters are the renderer's.
NATIVE_MODELS = {
    "mitsuba:roughconductor": (("alpha", 1), ("eta", 3), ("k", 3)),
    "mitsuba:roughplastic": (("diffuse_reflectance", 3), ("alpha", 1), ("int_ior", 1), ("specular_reflectance", 3)),
    "mitsuba:principled": (("base_color", 3), ("roughness", 1), ("metallic", 1), ("specular", 1), ("anisotropic", 1),
                           ("sheen", 1), ("clearcoat", 1), ("clearcoat_gloss", 1)),
    "gltf:metallic_roughness": (("base_color", 3), ("metallic", 1), ("roughness", 1)),
    "blender:principled": (("base_color", 3), ("metallic", 1), ("roughness", 1), ("ior", 1),
                           ("specular_tint", 1)),
}


def test_names_are_spec4():
    assert names() == sorted([*LIBRARY_MODELS, *NATIVE_MODELS])


@pytest.mark.parametrize("name", sorted(NATIVE_MODELS))
def test_native_parameter_table_is_spec13(name):
    model = get(name)
    assert model.name == name and model.is_native and model.target == name.split(":")[0]
    assert tuple((p.name, p.channels) for p in model.params) == NATIVE_MODELS[name]
    assert model.citation and model.doc


@pytest.mark.parametrize("name", sorted(LIBRARY_MODELS))
def test_parameter_table_is_spec4(name):
    model = get(name)
    assert model.name == name
    assert tuple((p.name, p.channels) for p in model.params) == LIBRARY_MODELS[name]
    assert model.citation and model.doc
    assert model.reciprocal == (name != "phong_classic")
    for p in model.params:
        assert p.lower <= p.default <= p.upper
        if p.role == "exponent":
            assert p.upper >= 1e4
        if p.role == "roughness" and p.scale == "log":
            assert p.lower <= 1e-4
        if p.role == "fresnel":
            assert (p.lower, p.upper) == (0.0, 1.0)


@pytest.mark.parametrize("name", ["phong", "phong_classic", "blinn_phong"])
def test_lecture_models_document_lecture_and_brdf_forms(name):
    doc = get(name).doc
    assert "Lecture form" in doc and "BRDF form" in doc
    assert "I_L" in doc and "(n.l)" in doc


def test_oren_nayar_documents_radians():
    assert "radians" in get("oren_nayar").doc and "radians" in get("oren_nayar").param("sigma").doc


def test_composite_names_and_lookup():
    m = get("lambert+ggx+ggx")
    assert m.param_names == ("kd", "ggx1.ks", "ggx1.alpha", "ggx1.f0", "ggx2.ks", "ggx2.alpha", "ggx2.f0")
    assert get(" Lambert + GGX +ggx ") is m  # case-insensitive, spaces ignored, cached
    assert [c.name for c in m.components] == ["lambert", "ggx", "ggx"]
    assert m.reciprocal and not get("lambert+phong_classic").reciprocal
    assert get("ggx+blinn_phong").param_names == (
        "kd", "ggx1.ks", "ggx1.alpha", "ggx1.f0", "blinn_phong1.ks", "blinn_phong1.n"
    )
    assert get("oren_nayar+ward").param_names == (
        "kd", "oren_nayar1.sigma", "ward1.ks", "ward1.alpha_x", "ward1.alpha_y"
    )
    assert get("lambert+ashikhmin_shirley").param_names[:2] == ("kd", "ashikhmin_shirley1.rd")
    assert get("ggx") is get("GGX") and get("ggx").components == ()
    with pytest.raises(ValueError, match="one diffuse"):
        get("lambert+oren_nayar")
    with pytest.raises(KeyError, match="unknown model"):
        get("lambert+nosuch")
    with pytest.raises(KeyError):
        get("lambert++ggx")


def test_lafortune_lobes():
    m3 = get("lafortune", lobes=3)
    assert m3 is get("lafortune3") and m3.name == "lafortune3"
    assert m3.param_names[:5] == ("kd", "rho1", "cx1", "cz1", "n1") and m3.param_names[-1] == "n3"
    assert len({m3.param(f"n{j}").default for j in (1, 2, 3)}) == 3  # lobes start distinct
    assert get("lafortune", lobes=1) is get("lafortune")
    with pytest.raises(ValueError):
        get("lafortune", lobes=0)


def _pairs(n=48, seed=0):
    """Random pairs plus mirror pairs (where sharp lobes are not ~0)."""
    rng = np.random.default_rng(seed)
    th = np.arccos(rng.uniform(0.05, 1.0, (2, n)))
    ph = rng.uniform(0, 2 * np.pi, (2, n))
    v = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    wi = np.concatenate([v[0], v[0]])
    wo = np.concatenate([v[1], v[0] * [-1.0, -1.0, 1.0]])
    return wi, wo


def _affine_defect(model, base, names_, rng, wi, wo):
    """Relative misfit of f as a jointly affine function of the parameters ``names_`` (others at
    ``base``): f(lam) vs f(lam0) + sum_j (lam_j - lam0_j) B_j, lam0 = lower bounds, B_j from a
    probe step of half the parameter's range."""

    def f(q):
        return np.asarray(model.eval(q, wi, wo))

    # Param.finite_range: the bounds, the physical range where a bound is infinite (ks, kd, ...).
    lam0 = {k: np.full_like(base[k], model.param(k).finite_range[0]) for k in names_}
    step = {k: 0.5 * (model.param(k).finite_range[1] - model.param(k).finite_range[0]) for k in names_}
    ref = dict(base, **lam0)
    f0 = f(ref)
    lam = {k: lam0[k] + rng.uniform(0.1, 0.4, base[k].shape) * 2 * step[k] for k in names_}
    pred = f0.copy()
    for k in names_:
        bj = (f(dict(ref, **{k: lam0[k] + step[k]})) - f0) / step[k]
        d = lam[k] - lam0[k]
        pred = pred + (d if d.size > 1 else d[0]) * bj
    got = f(dict(base, **lam))
    return np.max(np.abs(got - pred)) / max(np.max(np.abs(got)), 1e-300)


@pytest.mark.parametrize("name", sorted(LIBRARY_MODELS) + ["lambert+ggx+ggx", "lafortune3"])
def test_linear_flags_are_exact_and_maximal(name):
    model = get(name)
    wi, wo = _pairs()
    rng = np.random.default_rng(1)
    base = {k: np.asarray(v) for k, v in model.defaults().items()}
    lin = [p.name for p in model.params if p.linear]
    assert lin, "every model has a linear albedo"
    assert all(model.param(k).lower == 0.0 for k in lin)
    assert _affine_defect(model, base, lin, rng, wi, wo) < 1e-10
    for p in model.params:
        if not p.linear:
            # marking it linear too would be wrong: the model is not jointly affine in it
            assert _affine_defect(model, base, lin + [p.name], rng, wi, wo) > 1e-6, p.name


@pytest.mark.parametrize("name", sorted(LIBRARY_MODELS) + ["lambert+ggx+ggx"])
def test_solver_box_roundtrip_and_samples_in_bounds(name):
    """Samples lie in the bounds, and the stock solvers' map into the box (solver_optx.to_box) is exact
    on them with every model's bounds (infinite sides, log axes)."""
    from brdffit.fitting.solver_optx import from_box, to_box

    model = get(name)
    lo, hi = model.bounds()
    assert np.all(lo < np.inf) and np.all(hi > -np.inf)
    for key in jax.random.split(jax.random.key(0), 4):
        p = model.sample(key)
        v = np.asarray(model.flatten(p))
        assert np.all((lo <= v) & (v <= hi))
        np.testing.assert_allclose(to_box(from_box(v, lo, hi), lo, hi), v, rtol=1e-9, atol=1e-12)
    # The corner of the finite box (the physical range standing in for an infinite bound).
    flo = np.concatenate([np.full(model.size(p), p.finite_range[0]) for p in model.params])
    np.testing.assert_allclose(to_box(from_box(flo, lo, hi), lo, hi), flo, atol=1e-12)


def test_parameter_table_text_as_brdffit_models_prints_it():
    """``Model.table()`` (what ``brdffit models`` prints), written out by hand from the parameter
    tables of ggx.py and oren_nayar.py: columns aligned, bounds in the files' notation (pi/2, 1e-4,
    inf with an open bracket), "yes" for the linear parameters, no trailing blanks."""
    assert get("ggx").table() == (
        "name   channels  bounds       physical   default  role       linear\n"
        "kd     3         [0, inf)     [0, 1]     0.1      albedo     yes\n"
        "ks     3         [0, inf)     [0, 1]     0.5      albedo     yes\n"
        "alpha  1         [1e-4, inf)  [1e-4, 1]  0.2      roughness\n"
        "f0     1         [0, 1]       [0, 1]     0.04     fresnel"
    )
    assert get("oren_nayar").table() == (
        "name   channels  bounds    physical   default  role       linear\n"
        "kd     3         [0, inf)  [0, 1]     0.5      albedo     yes\n"
        "sigma  1         [0, inf)  [0, pi/2]  0.3      roughness"
    )
    assert get("lambert+ggx").table().splitlines()[2] == (
        "ggx1.ks     3         [0, inf)     [0, 1]     0.5      albedo     yes"
    )


def test_model_repr_names_parameters_with_their_sizes_and_the_first_citation_line():
    assert repr(get("oren_nayar")) == (
        "Model('oren_nayar': kd(3), sigma; M. Oren, S. K. Nayar, Generalization of Lambert's Reflectance Model, "
        "SIGGRAPH 1994)"
    )
    assert repr(get("ggx").with_channels(1)).startswith("Model('ggx': kd, ks, alpha, f0; Walter, Marschner")
    import dataclasses

    assert repr(dataclasses.replace(get("lambert"), citation="")) == "Model('lambert': kd(3); )"  # a user's model


def test_compose_of_nothing_says_so():
    from brdffit.models.compose import compose

    with pytest.raises(ValueError) as info:
        compose([])
    assert str(info.value) == "compose needs at least one model"


@pytest.mark.parametrize(("lower", "upper", "text"), [
    (-np.inf, np.inf, "(-inf, inf)"),  # both open; a lower bound of -inf is negative
    (0.0, np.pi / 2, "[0, pi/2]"),
    (1e-4, np.inf, "[1e-4, inf)"),
    (0.01, 1e4, "[0.01, 1e4]"),  # 0.01 still plain, 1e4 already scientific
    (-5e-3, 0.0099, "[-5e-3, 9.9e-3]"),
    (1e-3, 9999.0, "[1e-3, 9999]"),
])
def test_format_range_is_the_notation_of_the_model_files(lower, upper, text):
    from brdffit.models.base import format_range

    assert format_range(lower, upper) == text


def test_two_diffuse_terms_are_refused_with_both_named():
    with pytest.raises(ValueError) as err:
        get("oren_nayar+ggx+lambert")
    assert str(err.value) == "a composite has one diffuse term: oren_nayar and lambert would both be diffuse"


@pytest.mark.parametrize("name, owner", [("lambert+ggx+ggx", 0), ("ggx+oren_nayar", 1), ("oren_nayar+ggx", 0),
                                         ("ggx+blinn_phong", 0), ("ashikhmin_shirley+ggx", 1),
                                         ("ashikhmin_shirley+ashikhmin_shirley", None)])
def test_a_composite_is_the_sum_of_its_components_with_one_owner_of_kd(name, owner):
    """The naming scheme of ``compose`` (its docstring), evaluated: f is the sum of the components'
    own f, the shared kd going to the diffuse component (else the first component with a kd) and
    every other component's kd held at 0; without any kd there is none."""
    wi, wo = _pairs()
    m = get(name)
    rng = np.random.default_rng(3)
    params = {p.name: rng.uniform(0.2, 0.6, m.size(p)) for p in m.params}
    expected, seen = 0.0, {}
    for i, c in enumerate(m.components):
        seen[c.name] = seen.get(c.name, 0) + 1
        own = {}
        for q in c.params:
            if q.name == "kd":
                own["kd"] = params["kd"] if i == owner else np.zeros(c.size(q))
            else:
                own[q.name] = params[f"{c.name}{seen[c.name]}.{q.name}"]
        expected = expected + np.asarray(c.eval(own, wi, wo))
    assert ("kd" in m.param_names) == (owner is not None)
    np.testing.assert_allclose(np.asarray(m.eval(params, wi, wo)), expected, rtol=1e-12)


def test_a_composite_names_cites_and_documents_its_components():
    m = get("lambert+ggx+ggx")
    lam, ggx = get("lambert"), get("ggx")
    assert m.name == "lambert+ggx+ggx"
    assert m.citation == f"{lam.citation}; {ggx.citation}"  # each paper once
    assert m.doc.startswith("Composite model lambert+ggx+ggx: the sum of its components' BRDFs.\n\n")
    assert "Naming scheme" in m.doc  # compose's own docstring: how the parameters are named
    assert m.doc.endswith(f"\n\nComponents\n----------\nlambert: {lam.citation}\nggx: {ggx.citation}\nggx: {ggx.citation}")


def test_lobe_width_is_log_roughness_minus_log_exponent_summed_over_the_lobe():
    """The key that orders lobes of one kind (compose's docstring): for a two-roughness Ward lobe
    the log of the product, for Blinn-Phong minus the log of the exponent; ks plays no part."""
    from brdffit.models.compose import lobe_width

    ward = get("ward+ward")
    values = {"ward1.ks": np.array([0.3]), "ward1.alpha_x": np.array([0.5]), "ward1.alpha_y": np.array([0.1])}
    assert lobe_width(ward, ward.lobes[0], values) == pytest.approx(np.log(0.05), rel=1e-12)
    phong = get("lambert+blinn_phong+blinn_phong")
    for n in (200.0, 0.5):  # exponents need only be > 0
        values = {"blinn_phong2.ks": np.array([0.3, 0.2, 0.1]), "blinn_phong2.n": np.array([n])}
        assert lobe_width(phong, phong.lobes[1], values) == pytest.approx(-np.log(n), rel=1e-12)
    # 0-d arrays are arrays too
    values = {"ward1.ks": np.array(0.3), "ward1.alpha_x": np.array(0.2), "ward1.alpha_y": np.array(0.3)}
    assert lobe_width(ward, ward.lobes[0], values) == pytest.approx(np.log(0.06), rel=1e-12)


def test_a_composite_keeps_its_components_channel_count():
    from brdffit.models.compose import compose

    mono = compose([get("lambert").with_channels(1), get("ggx").with_channels(1)])
    assert mono.channels == 1 and mono.size(mono.param("kd")) == 1


def test_lookup_errors_name_the_known_models_and_what_lobes_applies_to():
    from brdffit.models import names

    with pytest.raises(KeyError) as err:
        get("lambert+nosuch")
    assert err.value.args[0] == f"unknown model 'nosuch' in 'lambert+nosuch'; known: {', '.join(names())}"
    assert "ashikhmin_shirley, blender:principled, blinn_phong, cook_torrance" in err.value.args[0]
    with pytest.raises(KeyError) as err:
        get("ggx", lobes=2)
    assert err.value.args[0] == "lobes= applies to 'lafortune' only, not 'ggx'"


@pytest.mark.parametrize("name", ["ggx", "blinn_phong", "oren_nayar"])
def test_sample_keeps_its_margin_from_both_ends_of_each_axis(name):
    """``sample(key, margin)`` keeps that fraction of each axis (log axes in log) away from both
    ends of the finite range: with margin 0.45 every value lies in the middle tenth."""
    model = get(name)
    for key in jax.random.split(jax.random.key(1), 8):
        p = model.sample(key, margin=0.45)
        for q in model.params:
            a, b = q.finite_range
            x = np.asarray(p[q.name], np.float64)
            if q.scale == "log":
                a, b, x = np.log(a), np.log(b), np.log(x)
            u = (x - a) / (b - a)
            assert np.all((u >= 0.45 - 1e-12) & (u <= 0.55 + 1e-12)), (q.name, u)


def test_bounds_written_as_integers_are_floats():
    """A model file may write ``Param("n", 1, 1, 100, 20, ...)``: its bounds and default are
    floats, and the model's flat bounds float64, as for every other model."""
    from brdffit.models.base import Model, Param

    n = Param("n", 1, 1, 100, 20, "exponent", doc="an exponent")
    assert all(type(v) is float for v in (n.lower, n.upper, n.default)) and n.physical == (1.0, 100.0)
    model = Model(name="integers", params=(Param("kd", 3, 0, 1, 1, "albedo", linear=True, doc="albedo"), n),
                  formula=lambda p, wi, wo: p["kd"] / np.pi, citation="none: a test model")
    lo, hi = model.bounds()
    assert lo.dtype == hi.dtype == np.float64
    np.testing.assert_array_equal(hi, [1.0, 1.0, 1.0, 100.0])
