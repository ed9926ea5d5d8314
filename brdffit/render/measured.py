"""RGL-EPFL measured data (Dupuy & Jakob 2018) in Mitsuba's own ``measured`` plugin (docs/formats.md#readers-and-writers): the
reader holds the one door to the plugin (:func:`brdffit.io.rgl.load_measured`) and its evaluation
(:func:`brdffit.io.rgl.eval_measured`), through the lowest Mitsuba layer; importable from here,
where the renderer's modules look for them."""

from __future__ import annotations

from ..io.rgl import eval_measured, eval_plugin, load_measured  # noqa: F401
