"""One process of a two-process fit_btf run (tests/test_btf_fit.py): loopback jax.distributed.

Usage: python distributed_fit.py PORT PROCESS_ID BTF_FOLDER MODEL OUT_NPZ CACHE_DIR
"""

import sys

import jax

port, pid, folder, model, out_npz, cache = sys.argv[1:7]
jax.distributed.initialize(coordinator_address=f"127.0.0.1:{port}", num_processes=2, process_id=int(pid))

import numpy as np  # noqa: E402

import brdffit  # noqa: E402

btf = brdffit.load_btf(folder, tile=2, cache_dir=cache)
maps = brdffit.fit_btf(btf, model, progress=False)
arrays = {f"param:{k}": v for k, v in maps.params.items()}
np.savez(out_npz, loss=maps.loss, converged=maps.converged, steps=maps.steps, processes=maps.info["processes"], **arrays)
