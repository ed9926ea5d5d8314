"""Lanes: how the stages of a fit (``stages``) are laid out over many solves, on this process's devices.

A *lane* is one solve (one start of one fit). A compiled stage works on a chunk of lanes: each lane has
its own row of the per-fit arrays (``Data`` fields with a leading axis: :func:`per_lane`) beside the
arrays every lane shares (``Data`` fields without one: the directions of a BTF's texels, their weights),
so a BTF's directions are held once, not once per texel. :func:`map_lanes` runs a stage's function of
one lane over a chunk; :func:`shared_geometry` computes the direction-only terms once for a chunk whose
lanes share their directions.

How a backend is used (:func:`plan`, unless the caller sets ``chunk`` and ``lanes``):

- CPU: chunks of ``CPU_CHUNK`` lanes, ``CPU_LANES`` of them vectorised at a time inside the compiled
  call (one: a loop over the unbatched solve, :func:`map_lanes`; a vectorised solve gains little on a
  CPU beyond sharing each operation's overhead, and its arrays must stay in the cache), as many chunks
  at once as the machine has cores (XLA runs a call without the GIL).
- GPU (and other accelerators): one call holds up to ``DEVICE_CHUNK`` lanes, all vectorised; the
  lane axis is split over the process's devices (:func:`place_lanes`).
"""

from __future__ import annotations

import dataclasses
import os
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np

from .problem import Data

if TYPE_CHECKING:
    from .objective import Objective


#: Lanes per compiled call and lanes vectorised together on a CPU (see the module docstring). One lane at a
#: time: vectorising is slower on 2 cores (a 64 x 64 ggx BTF, warm: 768-792 texels/s one lane at a time,
#: 662-686 with 4, 596-603 with 16; one evaluation of ggx on UBO-81 holds ~20 arrays of 6561 values, and
#: several lanes' no longer fit the core's cache), and a lane computed alone is
#: computed identically whatever its chunk holds, so a BTF's maps do not depend on how its tiles were
#: grouped (processes, Dask workers, a resumed run).
CPU_CHUNK = 64
CPU_LANES = 1
#: Lanes per compiled call on an accelerator, all vectorised, at most: ggx on UBO-81 took 30 GB of an H200
#: at 16,384 lanes (about 2 MB a lane), so a device with less memory gets fewer (``plan``).
DEVICE_CHUNK = 16384
DEVICE_BYTES_PER_LANE = 2 * 2**20


@dataclasses.dataclass(frozen=True)
class Plan:
    """How lanes run: ``chunk`` lanes per compiled call (a multiple of ``lanes``), ``lanes`` vectorised
    together inside it, ``workers`` calls at once, on ``devices`` (the lane axis split over them)."""

    chunk: int
    lanes: int
    workers: int
    devices: tuple
    #: Ratio of one compiled size to the next (``sizes``): on an accelerator a program takes seconds to
    #: compile, so few sizes there (measured on an H200: 12 s of compiling in a first run).
    step: int = 4

    def sizes(self, n: int) -> list[tuple[int, int]]:
        """(lanes, compiled size) of each call for n lanes, each call's lanes padded to the next of a few
        sizes (one lane per device times a power of ``step``, at most ``chunk``), so that few programs are
        compiled. Lanes one at a time (a CPU's loop, :func:`map_lanes`, which runs a call's own lanes and
        not its padding): the lanes split evenly into a multiple of ``workers`` calls, so that every core
        has as much to do (64 lanes on two cores: two calls of 32, not one of 64 beside an idle core).
        Vectorised lanes (an accelerator's, where the padding is computed too): full chunks, then the rest."""
        if self.lanes == 1 and n:
            calls = min(n, self.workers * -(-n // (self.workers * self.chunk)))
            counts = [n // calls + (i < n % calls) for i in range(calls)]
        else:
            counts = [self.chunk] * (n // self.chunk) + ([n % self.chunk] if n % self.chunk else [])
        return [(count, self._size(count)) for count in counts]

    def _size(self, count: int) -> int:
        size = len(self.devices)
        while size < count:
            size *= self.step
        return min(size, self.chunk)


def plan(chunk: int | None = None, lanes: int | None = None) -> Plan:
    """The :class:`Plan` for this process's devices (``chunk`` / ``lanes`` override the backend's)."""
    devices = tuple(jax.local_devices())  # under jax.distributed, this process's own
    if devices[0].platform == "cpu":
        lanes = lanes or CPU_LANES
        chunk = chunk or CPU_CHUNK
        workers = max(1, min(_cores(), 8))
        devices = devices[:1]  # several host "devices" share the same cores: threads use them
    else:
        if chunk is None:
            limit = (devices[0].memory_stats() or {}).get("bytes_limit", 0)
            fits = int(0.5 * limit / DEVICE_BYTES_PER_LANE) if limit else DEVICE_CHUNK
            chunk = max(256, min(DEVICE_CHUNK, fits))
        lanes = lanes or chunk
        workers = 1
    unit = lanes * len(devices)
    chunk = max(unit, -(-chunk // unit) * unit)
    return Plan(chunk=chunk, lanes=lanes, workers=workers, devices=devices, step=4 if devices[0].platform == "cpu" else 256)


def _cores() -> int:
    """The cores this process may run on (its affinity: a container's or ``taskset``'s share, not the
    machine's count)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


# -- a chunk's lanes ----------------------------------------------------------------------------------
def gather_rows(a, idx):
    """Rows ``idx`` of an array (NumPy stays NumPy: gathered on the host, not on the device)."""
    return a[idx] if isinstance(a, np.ndarray) else jnp.take(a, idx, axis=0)


def place_lanes(tree, devices):
    """The lane axis of every array split over ``devices`` (one device: as it is)."""
    if len(devices) == 1:
        return tree
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    mesh = Mesh(np.asarray(devices), ("lanes",))
    return jax.device_put(tree, NamedSharding(mesh, PartitionSpec("lanes")))


#: Array ranks of one fit's ``Data`` fields; a field of one more rank holds one row per lane.
_RANKS = Data(wi=2, wo=2, ref=2, sqrt_w=2, cos_i=2, floor=1)


def per_lane(data: Data) -> Data:
    """True for the fields that hold one row per lane (a leading axis), False for shared ones."""
    return Data(*(jnp.ndim(a) == r + 1 for a, r in zip(data, _RANKS)))


def _split(data: Data):
    lane = per_lane(data)
    return (Data(*(a if m else None for a, m in zip(data, lane))),
            Data(*(None if m else a for a, m in zip(data, lane))))


def _join(own: Data, shared: Data) -> Data:
    return Data(*(a if a is not None else b for a, b in zip(own, shared)))


def map_lanes(fn, lane_args, data: Data, lanes: int, count):
    """``fn(lane_args_i, data_i)`` for every lane i (the leading axis of ``lane_args`` and of ``data``'s
    per-lane fields), ``lanes`` of them vectorised at a time; shared fields are passed whole.

    One lane at a time (a CPU's lanes) is a loop over the unbatched ``fn``: a vectorised batch of one gave
    the same run time through a larger program (ggx's round stage lowered in 0.8-1.0 s and compiled in
    4.4-4.6 s, against 0.54 s and 3.4 s). Its trip count is ``count``, a run-time scalar (the call's own
    lanes, ``Plan.sizes``): the lanes after it, a compiled size's padding, are not computed (their outputs
    are zeros), and one program serves a call of any count up to its size. A lane's numbers must not depend
    on the program's size (a BTF's maps must not depend on how its tiles were grouped), so the loop is one
    XLA cannot see through: a trip count it knew would let it unroll a loop of one lane into its
    surroundings, and a single lane's arrays are doubled (an axis of length one is laid out otherwise);
    either changed the last bits of a lane's result."""
    own, shared = _split(data)
    if lanes > 1:
        return jax.lax.map(lambda x: fn(x[0], _join(x[1], shared)), (lane_args, own), batch_size=lanes)
    lanes_in = (lane_args, own)
    n = jax.tree_util.tree_leaves(lanes_in)[0].shape[0]
    if n == 1:
        lanes_in = jax.tree_util.tree_map(lambda a: jnp.concatenate([a, a]), lanes_in)
    out = jax.eval_shape(lambda x: fn(x[0], _join(x[1], shared)), jax.tree_util.tree_map(lambda a: a[0], lanes_in))

    def one(i, acc):
        x = jax.tree_util.tree_map(lambda a: a[i], lanes_in)
        return jax.tree_util.tree_map(lambda o, v: o.at[i].set(v), acc, fn(x[0], _join(x[1], shared)))

    empty = jax.tree_util.tree_map(lambda s: jnp.zeros((n, *s.shape), s.dtype), out)
    return jax.lax.fori_loop(0, jnp.minimum(count, n), one, empty)


def shared_geometry(objective: Objective, data: Data):
    """The direction-only terms of a separable model (``objective.precompute_geometry``) when every lane
    shares its directions (a BTF's texels): computed once per call, outside the lanes' loop; else None."""
    lane = per_lane(data)
    if lane.wi or lane.wo:
        return None
    return objective.geometry(in_solve_dtype(data))


def in_solve_dtype(data: Data) -> Data:
    """The data in the solve's precision (a BTF's values arrive as float32, as stored)."""
    dtype = data.wi.dtype
    return data._replace(ref=data.ref.astype(dtype))
