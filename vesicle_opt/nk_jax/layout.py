"""Where the grid fields live: one device, or split along the first grid axis across devices.

``GridLayout(shape, devices)`` builds a ``jax.sharding.Mesh`` of the devices with one axis
``"grid"`` and the ``NamedSharding`` ``P("grid")``: device j holds the slab of rows
[j n_0/D, (j+1) n_0/D) of every field (n_0 must be divisible by D; ``choose_devices`` picks the
largest D <= the devices available that divides it). XLA's SPMD partitioner then runs the FFTs on
the sharded fields (its own transforms, with the all-to-all transposes they need) and the sums of
E, A, B and of the inner products as cross-device reductions; the Newton and CG control flow sees
scalars only. The same code runs on one CPU, several emulated host devices
(``XLA_FLAGS=--xla_force_host_platform_device_count=D``, set before jax is imported), several
GPUs of one host, and several hosts after ``jax.distributed.initialize()`` (``jax.devices()`` is
then the global list; ``put`` and ``get`` go through ``make_array_from_callback`` and
``process_allgather`` so every process holds the full start and result on its host).
"""

from __future__ import annotations

import jax
import numpy as np
from jax.experimental import multihost_utils
from jax.sharding import Mesh, NamedSharding, PartitionSpec

AXIS = "grid"


def choose_devices(n0: int, devices=None) -> list:
    """The largest prefix of ``devices`` (default ``jax.devices()``) whose length divides n0."""
    devices = list(jax.devices() if devices is None else devices)
    count = len(devices)
    while n0 % count:
        count -= 1
    return devices[:count]


class GridLayout:
    def __init__(self, shape, devices=None):
        self.shape = tuple(int(k) for k in shape)
        self.devices = choose_devices(self.shape[0], devices)
        self.count = len(self.devices)
        if self.count > 1:
            self.mesh = Mesh(np.array(self.devices), (AXIS,))
            self.sharding = NamedSharding(self.mesh, PartitionSpec(AXIS))
        else:
            self.mesh = None
            self.sharding = jax.sharding.SingleDeviceSharding(self.devices[0])

    def constrain(self, x):
        """Inside a traced kernel: keep a field split along the first axis (no-op on one device)."""
        if self.count == 1:
            return x
        return jax.lax.with_sharding_constraint(x, self.sharding)

    def put(self, values: np.ndarray):
        """A host vector (node order) as a device field of grid shape with this layout."""
        host = np.ascontiguousarray(np.asarray(values, float).reshape(self.shape))
        return jax.make_array_from_callback(self.shape, self.sharding, lambda index: host[index])

    def get(self, field) -> np.ndarray:
        """A device field as a host vector in node order (every process gets all of it)."""
        if jax.process_count() > 1:
            field = multihost_utils.process_allgather(field, tiled=True)
        return np.asarray(field, float).ravel()
