"""The one gate to colour-science (its CIE tables serve the Cornell reader's spectra and the conductors'
spectral fits): ``colour`` imported without its side effect on the process.

colour 0.4 sets NumPy's print options for the whole process when it is imported
(``np.set_printoptions(legacy="1.13")``): after a Cornell file was read, or a conductor converted, a
user's arrays and brdffit's own ``FitResult`` printed otherwise (``kd=[ 0.3  0.2  0.1]``). Whatever the
options were before the import are put back.
"""

from __future__ import annotations


def import_colour():
    """The ``colour`` module, NumPy's print options left as they were."""
    import numpy as np

    saved = np.get_printoptions()
    try:
        import colour as module
    finally:
        np.set_printoptions(**saved)
    return module
