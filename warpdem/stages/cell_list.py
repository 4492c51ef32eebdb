"""Cell list for the Verlet neighbour search, made only of plain kernel launches.

Warp's ``wp.HashGrid.build`` allocates, clears memory and sorts with CUB, so it runs every step
(it cannot sit in a conditional CUDA-graph node) although the Verlet list is rebuilt on only a
few per cent of the steps. :class:`CellList` replaces it: a counting sort of the spheres into
the buckets of a spatial hash, done by a fixed sequence of kernel launches whose sizes depend
only on the number of spheres, each of which returns at once when the device flag
``rebuild[0]`` is 0. The whole sequence therefore sits unconditionally in a CUDA graph and
costs a few empty launches on steps without a rebuild. Nothing is allocated, cleared with a
memset or read back to the host after construction.

Layout. Space is cut into cubic cells of side ``cell_size`` [m] (integer coordinates
c = floor(x / cell_size)); a cell of a world is hashed (with the world index mixed in, since
worlds share space) into one of ``num_buckets`` buckets (a power of two). The spheres of active
bodies are sorted by bucket (``sorted_sphere``, with each entry's cell and world in
``sorted_cell`` so that a query skips the other cells and worlds that share a bucket); bucket
``b`` holds the entries ``bucket_start[b] .. bucket_start[b] + bucket_count[b]``.

Build (each launch returns at once unless ``rebuild[0]``):

1. clear the bucket counts;
2. count: each sphere of an active body takes a rank in its bucket (``wp.atomic_add``);
3. exclusive scan of the counts into ``bucket_start``: strided chunks of ``SCAN_CHUNK``
   buckets are summed level by level until at most ``SCAN_TOP`` sums are left, one thread scans
   those, and the offsets are spread back down, level by level (5 launches for up to 2^22
   buckets);
4. scatter: each sphere is written at ``bucket_start[bucket] + rank`` (no atomics).

The order within a bucket follows the atomics (not deterministic on a GPU), but the list
kernel (:func:`build_neighbour_list_from_cells_kernel`) inserts each neighbour in index order
(:func:`warpdem.kernels.verlet_candidate_function`, shared with the hash-grid kernel), so the list
is the same as the hash grid's, entry for entry, unless a row overflows (an error anyway).
"""
from __future__ import annotations

import functools

import numpy as np
import warp as wp

from ..kernels import ListSpheres, VerletBuild, WallSet, finish_verlet_row, verlet_candidate_function
from ..layouts import DEFAULT_SLOT_LAYOUT

wp.set_module_options({"enable_backward": False, "fast_math": True})

# exclusive scan: buckets summed per chunk at each level, and the largest count scanned by one thread
SCAN_CHUNK = 64
SCAN_TOP = 1024
# bucket table: about this many buckets per sphere, a power of two within these bounds
BUCKETS_PER_SPHERE = 2
MIN_BUCKETS = 64
MAX_BUCKETS = 1 << 22
# threads of the grid-stride launches (clear, count, scatter): enough to fill a GPU on a
# rebuild, few enough that an early exit is one short wave
MAX_STRIDE_THREADS = 1 << 16
# integer cell coordinates are clamped to +- this (far-away spheres share the border cells)
CELL_LIMIT = wp.constant(1 << 30)
# the query box is widened by this fraction of the search radius (plus a float32 rounding of
# the coordinate), so that a float rounding of x / cell_size never leaves a neighbour's cell out
QUERY_PAD = wp.constant(1.0e-3)
COORD_ROUNDING = wp.constant(1.0e-6)

HASH_M1 = wp.constant(wp.uint32(0x85EBCA6B))
HASH_M2 = wp.constant(wp.uint32(0xC2B2AE35))
HASH_WORLD = wp.constant(wp.uint32(0x9E3779B9))


@wp.struct
class CellTable:
    """The cell list's arrays, as the list kernel reads them."""

    cell_size: float  # side of a cubic cell [m]
    bucket_mask: int  # num_buckets - 1 (num_buckets a power of two)
    bucket_start: wp.array(dtype=int)  # first entry of each bucket in sorted_*
    bucket_count: wp.array(dtype=int)  # entries of each bucket
    sorted_sphere: wp.array(dtype=int)  # sphere index of each entry, grouped by bucket
    sorted_cell: wp.array(dtype=wp.vec4i)  # (cx, cy, cz, world) of each entry


@wp.func
def mix32(h: wp.uint32):
    """MurmurHash3's 32-bit finaliser: every input bit affects every output bit."""
    h = h ^ (h >> wp.uint32(16))
    h = h * HASH_M1
    h = h ^ (h >> wp.uint32(13))
    h = h * HASH_M2
    return h ^ (h >> wp.uint32(16))


@wp.func
def bucket_of(cell: wp.vec4i, bucket_mask: int):
    """Bucket of a cell (cx, cy, cz, world): a hash of all four integers, masked."""
    h = mix32(wp.uint32(cell[3]) * HASH_WORLD + wp.uint32(cell[0]))
    h = mix32(h + wp.uint32(cell[1]))
    h = mix32(h + wp.uint32(cell[2]))
    return int(h & wp.uint32(bucket_mask))


@wp.func
def cell_coordinate(x: float, cell_size: float):
    """floor(x / cell_size), clamped to +- CELL_LIMIT (0 for NaN)."""
    c = wp.floor(x / cell_size)
    if c >= float(CELL_LIMIT):
        return CELL_LIMIT
    if c <= -float(CELL_LIMIT):
        return -CELL_LIMIT
    if wp.isnan(c):
        return 0
    return int(c)


@wp.func
def cell_of(x: wp.vec3, world: int, cell_size: float):
    """The cell (cx, cy, cz, world) holding the point ``x`` [m] of ``world``."""
    return wp.vec4i(cell_coordinate(x[0], cell_size), cell_coordinate(x[1], cell_size),
                    cell_coordinate(x[2], cell_size), world)


@wp.kernel
def clear_counts(bucket_count: wp.array(dtype=int), num_buckets: int, stride: int, rebuild: wp.array(dtype=int)):
    """bucket_count[:] = 0 (grid-stride, ``stride`` = the launch's thread count); nothing
    unless ``rebuild[0]``."""
    if rebuild[0] == 0:
        return
    for k in range(wp.tid(), num_buckets, stride):
        bucket_count[k] = 0


@wp.kernel
def count_spheres(
    sphere_x: wp.array(dtype=wp.vec3),
    sphere_world: wp.array(dtype=int),
    sphere_body: wp.array(dtype=int),
    body_active: wp.array(dtype=int),
    num_spheres: int,
    stride: int,
    cell_size: float,
    bucket_mask: int,
    sphere_cell: wp.array(dtype=wp.vec4i),
    sphere_bucket: wp.array(dtype=int),
    sphere_rank: wp.array(dtype=int),
    bucket_count: wp.array(dtype=int),
    rebuild: wp.array(dtype=int),
):
    """Each sphere of an active body: its cell, its bucket and its rank in the bucket (the
    bucket's count before it was added); a sphere of an inactive body gets bucket -1 (it is
    never a neighbour). Grid-stride, ``stride`` = the launch's thread count."""
    if rebuild[0] == 0:
        return
    for i in range(wp.tid(), num_spheres, stride):
        if body_active[sphere_body[i]] == 0:
            sphere_bucket[i] = -1
            continue
        cell = cell_of(sphere_x[i], sphere_world[i], cell_size)
        bucket = bucket_of(cell, bucket_mask)
        sphere_cell[i] = cell
        sphere_bucket[i] = bucket
        sphere_rank[i] = wp.atomic_add(bucket_count, bucket, 1)


@wp.kernel
def sum_chunks(values: wp.array(dtype=int), num_chunks: int, chunk_len: int, sums: wp.array(dtype=int),
               rebuild: wp.array(dtype=int)):
    """sums[t] = sum of chunk t = values[t + m num_chunks] for m < chunk_len (strided, so that
    neighbouring threads read neighbouring entries)."""
    if rebuild[0] == 0:
        return
    t = wp.tid()
    s = int(0)
    for m in range(chunk_len):
        s += values[t + m * num_chunks]
    sums[t] = s


@wp.kernel
def scan_serial(values: wp.array(dtype=int), num_values: int, offsets: wp.array(dtype=int),
                rebuild: wp.array(dtype=int)):
    """offsets = exclusive prefix sum of ``values[:num_values]`` (one thread)."""
    if rebuild[0] == 0:
        return
    running = int(0)
    for k in range(num_values):
        v = values[k]
        offsets[k] = running
        running += v


@wp.kernel
def spread_chunk_offsets(values: wp.array(dtype=int), num_chunks: int, chunk_len: int,
                         chunk_offsets: wp.array(dtype=int), offsets: wp.array(dtype=int),
                         rebuild: wp.array(dtype=int)):
    """Exclusive prefix sum within each strided chunk of ``values`` (as in :func:`sum_chunks`),
    started at the chunk's offset ``chunk_offsets[t]``: the offsets of the level below."""
    if rebuild[0] == 0:
        return
    t = wp.tid()
    running = chunk_offsets[t]
    for m in range(chunk_len):
        k = t + m * num_chunks
        v = values[k]
        offsets[k] = running
        running += v


@wp.kernel
def scatter_spheres(
    sphere_cell: wp.array(dtype=wp.vec4i),
    sphere_bucket: wp.array(dtype=int),
    sphere_rank: wp.array(dtype=int),
    bucket_start: wp.array(dtype=int),
    num_spheres: int,
    stride: int,
    sorted_sphere: wp.array(dtype=int),
    sorted_cell: wp.array(dtype=wp.vec4i),
    rebuild: wp.array(dtype=int),
):
    """Write each counted sphere at its bucket's start + its rank (grid-stride)."""
    if rebuild[0] == 0:
        return
    for i in range(wp.tid(), num_spheres, stride):
        bucket = sphere_bucket[i]
        if bucket < 0:
            continue
        slot = bucket_start[bucket] + sphere_rank[i]
        sorted_sphere[slot] = i
        sorted_cell[slot] = sphere_cell[i]


@functools.lru_cache(maxsize=None)
def build_neighbour_list_from_cells_kernel(layout: str = DEFAULT_SLOT_LAYOUT) -> "wp.Kernel":
    """The cell-list list kernel (:func:`build_neighbour_list_from_cells` below) writing the list
    in ``layout`` (:mod:`warpdem.layouts`), built once per layout."""
    add_verlet_candidate = verlet_candidate_function(layout)

    @wp.kernel
    def build_neighbour_list_from_cells(table: CellTable, spheres: ListSpheres, walls: WallSet, out: VerletBuild):
        """Verlet list from the cell list ``table``: the same outputs as
        :func:`warpdem.kernels.build_neighbour_list_kernel` (spheres of the same world and another,
        active body within r_i + r_j + skin, sorted by index; near static wall; build position;
        overflow), with the candidates taken from the cells that the box x_i +- (r_i + r_max + skin)
        [m] touches (3 per axis at most for r_i = r_max, as cell_size = 2 r_max + skin; the box is
        widened by a hair against float rounding). Does nothing unless ``out.rebuild[0]``."""
        if out.rebuild[0] == 0:
            return
        i = wp.tid()
        xi = spheres.position[i]
        ri = spheres.radius[i]
        b = spheres.body[i]
        world = spheres.world[i]
        active = spheres.body_active[b]
        n = int(0)
        n_dropped = int(0)
        if active != 0:
            reach = ri + spheres.max_radius + spheres.skin
            h = table.cell_size
            pad = wp.vec3(reach * (1.0 + QUERY_PAD)) + wp.vec3(wp.abs(xi[0]), wp.abs(xi[1]),
                                                               wp.abs(xi[2])) * COORD_ROUNDING
            lo = cell_of(xi - pad, world, h)
            hi = cell_of(xi + pad, world, h)
            for cz in range(lo[2], hi[2] + 1):
                for cy in range(lo[1], hi[1] + 1):
                    for cx in range(lo[0], hi[0] + 1):
                        cell = wp.vec4i(cx, cy, cz, world)
                        bucket = bucket_of(cell, table.bucket_mask)
                        start = table.bucket_start[bucket]
                        for slot in range(start, start + table.bucket_count[bucket]):
                            if not (table.sorted_cell[slot] == cell):  # another cell or world in this bucket
                                continue
                            n, n_dropped = add_verlet_candidate(table.sorted_sphere[slot], xi, ri, b, i, n,
                                                                n_dropped, spheres, out)
        finish_verlet_row(i, xi, ri, active, world, n, n_dropped, spheres, walls, out)

    return build_neighbour_list_from_cells


def bucket_count_for(num_spheres: int) -> int:
    """Buckets for ``num_spheres`` spheres: the power of two nearest above
    BUCKETS_PER_SPHERE x num_spheres, within [MIN_BUCKETS, MAX_BUCKETS]."""
    want = max(MIN_BUCKETS, BUCKETS_PER_SPHERE * int(num_spheres))
    return int(min(MAX_BUCKETS, 1 << (want - 1).bit_length()))


class CellList:
    """A hashed cell list of spheres, rebuilt on the device when ``rebuild[0]`` is set.

    Args:
        num_spheres: spheres of the model (the arrays given to :meth:`build` have this length).
        cell_size: side of a cell [m]; the list kernel needs cell_size >= 2 r_max + skin.
        device: Warp device.
        num_buckets: buckets of the hash table (a power of two; default
            :func:`bucket_count_for`). Fewer buckets only mean more cells per bucket
            (the query skips the other cells' entries), never a wrong list.

    Every launch's size is fixed here, so :meth:`build` (and the list kernel
    :func:`build_neighbour_list_from_cells_kernel` over ``table``) can be captured once in a CUDA graph
    and replayed whatever ``rebuild[0]`` holds.
    """

    def __init__(self, num_spheres: int, cell_size: float, device, num_buckets: int | None = None) -> None:
        self.num_spheres = int(num_spheres)
        self.cell_size = float(cell_size)
        if not self.cell_size > 0:
            raise ValueError(f"cell_size must be > 0 m, got {cell_size}")
        self.num_buckets = bucket_count_for(num_spheres) if num_buckets is None else int(num_buckets)
        if self.num_buckets < 1 or self.num_buckets & (self.num_buckets - 1):
            raise ValueError(f"num_buckets must be a power of two, got {num_buckets}")
        self.device = wp.get_device(device)
        d = self.device
        n = max(self.num_spheres, 1)
        self.stride_threads = min(self.num_spheres, MAX_STRIDE_THREADS)
        self.bucket_count = wp.zeros(self.num_buckets, dtype=int, device=d)
        self.bucket_start = wp.zeros(self.num_buckets, dtype=int, device=d)
        self.sphere_cell = wp.zeros(n, dtype=wp.vec4i, device=d)
        self.sphere_bucket = wp.full(n, -1, dtype=int, device=d)
        self.sphere_rank = wp.zeros(n, dtype=int, device=d)
        self.sorted_sphere = wp.zeros(n, dtype=int, device=d)
        self.sorted_cell = wp.zeros(n, dtype=wp.vec4i, device=d)
        # scan levels: level 0 = bucket counts; level k+1 = sums of level k's chunks, until the
        # top level has at most SCAN_TOP entries; (values, offsets) per level above 0
        self.scan_levels: list[tuple[wp.array, wp.array]] = []
        size = self.num_buckets
        while size > SCAN_TOP:
            size //= SCAN_CHUNK
            self.scan_levels.append((wp.zeros(size, dtype=int, device=d), wp.zeros(size, dtype=int, device=d)))
        self.table = CellTable()
        self.table.cell_size = self.cell_size
        self.table.bucket_mask = self.num_buckets - 1
        self.table.bucket_start = self.bucket_start
        self.table.bucket_count = self.bucket_count
        self.table.sorted_sphere = self.sorted_sphere
        self.table.sorted_cell = self.sorted_cell

    def build(self, sphere_x: wp.array, sphere_world: wp.array, sphere_body: wp.array, body_active: wp.array,
              rebuild: wp.array) -> None:
        """Sort the spheres of active bodies (positions ``sphere_x`` [m], worlds, bodies, the
        bodies' active flags) into the table, if ``rebuild[0]`` is set on the device; else every
        launch returns at once. Launches only (capturable, no host read)."""
        d = self.device
        nb = self.num_buckets
        threads = self.stride_threads
        clear_threads = min(nb, MAX_STRIDE_THREADS)
        wp.launch(clear_counts, dim=clear_threads, inputs=[self.bucket_count, nb, clear_threads, rebuild], device=d)
        wp.launch(count_spheres, dim=threads, inputs=[
            sphere_x, sphere_world, sphere_body, body_active, self.num_spheres, threads, self.cell_size, nb - 1,
            self.sphere_cell, self.sphere_bucket, self.sphere_rank, self.bucket_count, rebuild], device=d)
        self._scan(rebuild)
        wp.launch(scatter_spheres, dim=threads, inputs=[
            self.sphere_cell, self.sphere_bucket, self.sphere_rank, self.bucket_start, self.num_spheres, threads,
            self.sorted_sphere, self.sorted_cell, rebuild], device=d)

    def _scan(self, rebuild: wp.array) -> None:
        """bucket_start = exclusive prefix sum of bucket_count (early-exit launches)."""
        d = self.device
        below = self.bucket_count
        for values, _ in self.scan_levels:  # up: chunk sums
            chunks = values.shape[0]
            wp.launch(sum_chunks, dim=chunks, inputs=[below, chunks, SCAN_CHUNK, values, rebuild], device=d)
            below = values
        top_values, top_offsets = self.scan_levels[-1] if self.scan_levels else (self.bucket_count, self.bucket_start)
        wp.launch(scan_serial, dim=1, inputs=[top_values, top_values.shape[0], top_offsets, rebuild], device=d)
        for k in range(len(self.scan_levels) - 1, -1, -1):  # down: spread the chunk offsets
            values_below = self.scan_levels[k - 1][0] if k > 0 else self.bucket_count
            offsets_below = self.scan_levels[k - 1][1] if k > 0 else self.bucket_start
            chunks = self.scan_levels[k][0].shape[0]
            wp.launch(spread_chunk_offsets, dim=chunks, inputs=[
                values_below, chunks, SCAN_CHUNK, self.scan_levels[k][1], offsets_below, rebuild], device=d)

    def bucket_ranges(self) -> tuple[np.ndarray, np.ndarray]:
        """(bucket_start, bucket_count) on the host (tests, diagnostics)."""
        return self.bucket_start.numpy(), self.bucket_count.numpy()
