"""Where the grid fields live: one device, or split along the first grid axis across devices.

``GridLayout(shape, devices)`` builds a ``jax.sharding.Mesh`` of the devices with one axis
``"grid"`` and the ``NamedSharding`` ``P("grid")``: device j holds the slab of rows
[j n_0/D, (j+1) n_0/D) of every field (n_0 must be divisible by D; ``choose_devices`` picks the
largest D <= the devices available that divides it). XLA's SPMD partitioner then runs the
pointwise arithmetic on the sharded fields; the sums of E, A, B and of the inner products are
``total`` / ``spectrum_total`` (``reduce``: row by row on the device that holds the row, then a
compensated combine in row order, the same bits on any D); the Newton and CG control flow sees
scalars only.

FFTs: XLA's SPMD partitioner does not split a multi-dimensional FFT; on a sharded field it
all-gathers the field and transforms it whole on every device (measured in the compiled program:
six all-gathers per Laplacian at 32^3 on two devices), which keeps neither the memory nor the work
per device at 1/D. So 3D grids with n_1 divisible by D use the slab decomposition here
(``rfftn``/``irfftn``, ``jax.shard_map``): the real FFTs along axes 1 and 2 on each device's slab,
one ``all_to_all`` that moves the split from axis 0 to axis 1, the complex FFT along axis 0; the
spectrum is then split along axis 1 (``P(None, "grid")``) with global indices unchanged, so every
symbol product in Fourier space is the same code on any layout. The inverse runs backwards. 2D
grids (the half spectrum's n_1/2 + 1 rows seldom divide by D) keep XLA's own transforms. The same code runs on one CPU, several emulated host devices
(``XLA_FLAGS=--xla_force_host_platform_device_count=D``, set before jax is imported), several
GPUs of one host, and several hosts after ``jax.distributed.initialize()`` (``jax.devices()`` is
then the global list; ``put`` and ``get`` go through ``make_array_from_callback`` and
``process_allgather`` so every process holds the full start and result on its host).
"""

from __future__ import annotations

import jax
import numpy as np
from jax.experimental import multihost_utils
import jax.numpy as jnp
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from vesicle_opt.nk_jax.reduce import neumaier_sum, row_sums, rows_total

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
        self.slab_fft = False
        if self.count > 1:
            self.mesh = Mesh(np.array(self.devices), (AXIS,))
            self.sharding = NamedSharding(self.mesh, PartitionSpec(AXIS))
            self.replicated = NamedSharding(self.mesh, PartitionSpec())
            self.slab_fft = len(self.shape) == 3 and self.shape[1] % self.count == 0
            if self.slab_fft:
                spec, kspec = PartitionSpec(AXIS), PartitionSpec(None, AXIS)
                self._fwd = jax.shard_map(self._slab_forward, mesh=self.mesh, in_specs=spec, out_specs=kspec)
                self._inv = jax.shard_map(self._slab_inverse, mesh=self.mesh, in_specs=kspec, out_specs=spec)
                self._kblocks = jax.shard_map(self._spectrum_blocks, mesh=self.mesh, in_specs=kspec, out_specs=spec)
            self._blocks = jax.shard_map(self._field_blocks, mesh=self.mesh, in_specs=PartitionSpec(AXIS),
                                         out_specs=PartitionSpec(AXIS))
        else:
            self.mesh = self.replicated = None
            self.sharding = jax.sharding.SingleDeviceSharding(self.devices[0])

    # --- transforms (module docstring) ---------------------------------------------------------
    def _slab_forward(self, x):
        y = jnp.fft.rfftn(x, axes=(1, 2))  # local slab (n0/D, n1, n2) -> (n0/D, n1, n2/2+1)
        y = jax.lax.all_to_all(y, AXIS, split_axis=1, concat_axis=0, tiled=True)  # (n0, n1/D, .)
        return jnp.fft.fft(y, axis=0)

    def _slab_inverse(self, yh):
        y = jnp.fft.ifft(yh, axis=0)
        y = jax.lax.all_to_all(y, AXIS, split_axis=0, concat_axis=1, tiled=True)  # (n0/D, n1, .)
        return jnp.fft.irfftn(y, s=self.shape[1:], axes=(1, 2))

    def rfftn(self, v):
        """The real FFT of a field (rfft layout, global indices; split along axis 1 when slab). On one
        device a 3D field is transformed in the slab order too (axes 1, 2, then 0): the same 1D
        transforms in the same order, so the spectrum has the same bits as on D slabs (measured
        equal; ``jnp.fft.rfftn`` differs from it by ~1e-15 relative)."""
        if self.slab_fft:
            return self._fwd(v)
        if self.count == 1 and len(self.shape) == 3:
            return jnp.fft.fft(jnp.fft.rfftn(v, axes=(1, 2)), axis=0)
        return jnp.fft.rfftn(v)

    def irfftn(self, vh):
        """The inverse of ``rfftn``: a real field with this layout."""
        if self.slab_fft:
            return self._inv(vh)
        if self.count == 1 and len(self.shape) == 3:
            return jnp.fft.irfftn(jnp.fft.ifft(vh, axis=0), s=self.shape[1:], axes=(1, 2))
        return self.constrain(jnp.fft.irfftn(vh, s=self.shape))

    # --- sums (``reduce``: the same bits on any number of devices) -----------------------------
    @staticmethod
    def _field_rows(x):
        return x.reshape(x.shape[0], -1)

    @staticmethod
    def _spectrum_rows(xh):
        return jnp.moveaxis(xh, 1, 0).reshape(xh.shape[1], -1)

    def _field_blocks(self, x):
        return row_sums(self._field_rows(x))

    def _spectrum_blocks(self, xh):
        return row_sums(self._spectrum_rows(xh))

    def _combine(self, blocks):
        return neumaier_sum(jax.lax.with_sharding_constraint(blocks, self.replicated))

    def total(self, x):
        """Sum of a field's entries: the rows along axis 0 (the split axis) summed one by one on
        the device that holds them (``reduce.row_sums``), then combined in row order with the
        rounding errors carried (``reduce.neumaier_sum``); on one device both in one loop."""
        if self.count == 1:
            return rows_total(self._field_rows(x))
        return self._combine(self._blocks(x))

    def spectrum_total(self, xh):
        """Sum over a spectrum (``rfftn`` layout) as ``total``, the rows along axis 1 in 3D (the
        slab spectrum's split axis), along axis 0 in 2D: the same rows on every device count."""
        three = len(self.shape) == 3
        if self.count == 1:
            return rows_total(self._spectrum_rows(xh) if three else self._field_rows(xh))
        if three and self.slab_fft:
            return self._combine(self._kblocks(xh))
        return self._combine(row_sums(self._spectrum_rows(xh) if three else self._field_rows(xh)))

    def dot(self, a, b):
        """sum a * b over the grid (``total``)."""
        return self.total(a * b)

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
