"""The disk cache's key, in process: a kept program is found again only by the same model (name,
channels, parameters), program name and shapes; a user's own formula is never kept. (The
cross-process behaviour is tests/test_program_cache.py, in subprocesses.) And where the cache lives:
BRDFFIT_CACHE (a folder, or off in any of its spellings), else the user's cache folder."""

from __future__ import annotations

import os
from pathlib import Path

import jax.numpy as jnp
import pytest

from brdffit import models
from brdffit.fitting import cache


@pytest.fixture
def folder(monkeypatch, tmp_path):
    monkeypatch.setitem(cache._STATE, "dir", tmp_path)  # as enable() sets it, without JAX's global config
    return tmp_path / "brdffit-programs"


def _program(factor):
    return lambda: (lambda x: x * factor)


X = (jnp.arange(3.0),)


def test_a_program_is_found_again_by_its_model_and_never_by_another(folder):
    phong, blinn = models.get("phong"), models.get("blinn_phong")  # the same parameters and shapes
    assert phong.param_names == blinn.param_names
    assert cache.load_or_compile(("t", phong), _program(2.0), X)(*X).tolist() == [0.0, 2.0, 4.0]
    assert cache.load_or_compile(("t", blinn), _program(3.0), X)(*X).tolist() == [0.0, 3.0, 6.0]
    assert len(list(folder.glob("*.bin"))) == 2
    # found again on disk (the build is not used): each model gets its own program back
    assert cache.load_or_compile(("t", blinn), _program(5.0), X)(*X).tolist() == [0.0, 3.0, 6.0]
    assert cache.load_or_compile(("t", phong), _program(5.0), X)(*X).tolist() == [0.0, 2.0, 4.0]
    # another channel count, program name or shape is another program
    assert cache.load_or_compile(("t", phong.with_channels(1)), _program(7.0), X)(*X).tolist() == [0.0, 7.0, 14.0]
    assert cache.load_or_compile(("u", phong), _program(11.0), X)(*X).tolist() == [0.0, 11.0, 22.0]
    y = (jnp.arange(2.0),)
    assert cache.load_or_compile(("t", phong), _program(13.0), y)(*y).tolist() == [0.0, 13.0]
    assert len(list(folder.glob("*.bin"))) == 5


def test_a_users_formula_or_an_unknown_key_part_is_compiled_every_time(folder):
    phong = models.get("phong")
    own = models.Model("mine", phong.params, lambda p, wi, wo: phong.formula(p, wi, wo), citation="")
    assert cache.load_or_compile(("t", own), _program(2.0), X)(*X).tolist() == [0.0, 2.0, 4.0]
    assert cache.load_or_compile(("t", own), _program(3.0), X)(*X).tolist() == [0.0, 3.0, 6.0]
    assert cache.load_or_compile(("t", object()), _program(4.0), X)(*X).tolist() == [0.0, 4.0, 8.0]
    assert not folder.exists() or not list(folder.glob("*.bin"))


@pytest.mark.parametrize("off", ["off", "OFF", " 0 ", "none", "false", "No"])
def test_every_spelling_of_off_disables_the_cache(monkeypatch, off):
    monkeypatch.setenv("BRDFFIT_CACHE", off)
    assert cache.cache_dir() is None


def test_the_cache_folder_is_the_setting_or_the_users_cache(monkeypatch, tmp_path):
    import platformdirs

    monkeypatch.setenv("BRDFFIT_CACHE", str(tmp_path / "c"))
    assert cache.cache_dir() == tmp_path / "c"
    monkeypatch.setenv("BRDFFIT_CACHE", "~/brdffit-cache")
    assert str(cache.cache_dir()).startswith(str(Path.home()))
    monkeypatch.delenv("BRDFFIT_CACHE")
    assert cache.cache_dir() == Path(platformdirs.user_cache_dir("brdffit")) / "jax"


def test_enable_points_jax_at_the_folder_once(tmp_path, monkeypatch):
    """``enable`` sets JAX's persistent cache to BRDFFIT_CACHE's folder (created) and keeps every
    program (no minimum compile time or size); a read-only place leaves the cache off."""
    import jax

    names = ("jax_compilation_cache_dir", "jax_persistent_cache_min_compile_time_secs",
             "jax_persistent_cache_min_entry_size_bytes")
    before = {n: getattr(jax.config, n) for n in names}
    monkeypatch.setitem(cache._STATE, "dir", None)
    try:
        monkeypatch.setenv("BRDFFIT_CACHE", str(tmp_path / "made" / "here"))
        path = cache.enable()
        assert path == tmp_path / "made" / "here" and path.is_dir() and cache._STATE["dir"] == path
        assert [getattr(jax.config, n) for n in names] == [str(path), 0.0, 0]
        assert cache.enable() == path
        blocker = tmp_path / "a-file"
        blocker.write_text("")
        monkeypatch.setenv("BRDFFIT_CACHE", str(blocker / "below"))  # mkdir fails below a file
        assert cache.enable() is None and cache._STATE["dir"] == path
        monkeypatch.setenv("BRDFFIT_CACHE", "off")
        assert cache.enable() is None
    finally:
        for n, value in before.items():
            jax.config.update(n, value)


def test_loaded_programs_are_bounded(tmp_path, monkeypatch):
    """A loaded XLA program holds about 300 memory mappings and a process may have 65 530: a test
    worker that had loaded about 210 programs segfaulted inside XLA on the next load. The process
    keeps the MAX_LOADED most recently used ones; the mappings of the others are let go."""
    import jax.numpy as jnp

    from brdffit.fitting import cache

    monkeypatch.setenv("BRDFFIT_CACHE", str(tmp_path / "c"))

    def maps() -> int:
        with open(f"/proc/{os.getpid()}/maps") as fh:
            return sum(1 for _ in fh)

    x = jnp.arange(4.0)
    before = maps()
    for k in range(cache.MAX_LOADED + 40):
        cache.compiled(("bounded-test", k), lambda k=k: (lambda a: jnp.sin(a * (k + 1)).sum()), x)
        assert len(cache._CACHE) <= cache.MAX_LOADED
    first = ("bounded-test", 0)
    assert not any(key == first for key, _ in cache._CACHE)  # the least recently used went first
    assert maps() - before < 400 * cache.MAX_LOADED


def test_the_source_hash_covers_subfolders_and_paths_of_fitting_and_models_only(tmp_path):
    """A kept program is found by brdffit's fitting and model sources: a file in a subfolder (a
    solver family moved into a package) or a file moved changes the hash; other packages do not."""
    for rel in ("fitting/driver.py", "fitting/solvers/lm.py", "models/ggx.py", "render/bsdf.py"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(f"# {rel}\n")
    before = cache.sources_hash(tmp_path)
    assert cache.sources_hash(tmp_path) == before  # a function of the files alone

    (tmp_path / "fitting/solvers/lm.py").write_text("# lm, changed\n")
    changed = cache.sources_hash(tmp_path)
    assert changed != before
    (tmp_path / "fitting/solvers/lm.py").rename(tmp_path / "fitting/solvers/bounded_lm.py")
    assert cache.sources_hash(tmp_path) != changed  # same content, another path
    moved = cache.sources_hash(tmp_path)
    (tmp_path / "render/bsdf.py").write_text("# a renderer change\n")
    assert cache.sources_hash(tmp_path) == moved
