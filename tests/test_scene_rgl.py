"""docs/scene.md#scene-aware-fitting "must show" on real data: on the grazing floor, the scene-aware ggx fit renders the scene
with lower FLIP than the plain fit for every shared RGL material, by more than it costs on the sphere
validation. Cheaper settings than benchmarks/bench_scene.py (which prints the full figures)."""

from __future__ import annotations

import pytest

from brdffit.scene.compare import scene_gain
from conftest import REPO, rgl_params


@pytest.mark.slow
@pytest.mark.parametrize("path", rgl_params())
def test_scene_aware_fit_wins_in_its_scene(path):
    g = scene_gain(path, REPO / "scenes" / "grazing_floor.xml", "floor", usage_spp=4, render_spp=16, sphere_size=48)
    print(g, g.gain, g.cost)
    assert g.scene_flip_scene < g.scene_flip_plain
    assert g.gain > g.cost
