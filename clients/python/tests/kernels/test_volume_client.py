"""wp.Volume's client (clients/python/weft/volume.py): the NanoVDB reader and writer, the
tile/voxel computations and the allocation calls, against brute-force NumPy references on fresh
random data; hostile NanoVDB buffers (truncated, wrong magic, counts and offsets past the end,
unsupported types) that must fail with a clear RuntimeError; Warp's test assets when present;
and end-to-end tests through the daemon's CREATE_VOLUME and the volume builtins (skipped when the
daemon answers "unknown operation"). Float values are compared with a float64 NumPy reference:
exactly for lookups and stores, within 1e-4 for trilinear samples and transforms of coordinates
of size ~100."""
import os
import struct
import time
import zlib

import numpy as np
import pytest

import weft as wp
from weft import volume as V

ASSETS = "/tmp/warp-compat/ref-1.19.0/warp/tests/assets"
LIN_TOL = 1e-4
DEV = "cpu"


@pytest.fixture(autouse=True)
def _on_device(device):
    global DEV
    DEV = device


# ---------------------------------------------------------------------------------------------
# helpers


def random_origins(rng, n, span=200):
    origins = np.unique(rng.integers(-span, span, size=(n, 3)) * 8, axis=0).astype(np.int32)
    rng.shuffle(origins)
    return origins


def random_masks(rng, n, density=0.5):
    bits = rng.random((n, 512)) < density
    bits[:, rng.integers(0, 512)] = True
    return np.packbits(bits, axis=1, bitorder="little").view("<u8").reshape(n, 8)


def random_grid(rng, grid_type, n=30, span=200):
    origins = random_origins(rng, n, span)
    n = origins.shape[0]
    masks = random_masks(rng, n)
    layout = V._LAYOUTS[grid_type]
    values, background = None, 0
    if grid_type not in (V.INDEX, V.ON_INDEX):
        if layout.scalar[1] == "f":
            values = (rng.normal(size=(n * 512, layout.components)) + 3.0).astype(layout.scalar)
            background = rng.normal(size=layout.components) - 5.0
        else:
            values = rng.integers(1, 10**6, size=(n * 512, layout.components)).astype(layout.scalar)
            background = rng.integers(-100, -1, size=layout.components)
    matrix = np.diag(rng.uniform(0.1, 2.0, 3))
    return V.GridContent(grid_type, origins, masks, values, background, matrix, rng.normal(size=3),
                         name=f"grid-{rng.integers(1 << 30)}")


def brute_voxels(origins, masks, active_only):
    out = []
    for origin, mask in zip(origins, masks):
        for b in range(512):
            if not active_only or (int(mask[b // 64]) >> (b % 64)) & 1:
                out.append((origin[0] + b // 64, origin[1] + (b // 8) % 8, origin[2] + b % 8))
    return np.array(out, dtype=np.int32).reshape(-1, 3)


def brute_lookup(grid, values, ijk):
    """Per point: (value, index) as the daemon's kernels define them (float64 values)."""
    leaf_of = {tuple(int(c) for c in o): i for i, o in enumerate(grid.origins)}
    bits = V._mask_bits(grid.masks)
    rank = np.cumsum(bits.ravel()).reshape(bits.shape) - 1
    comps = grid.layout.components
    vals, idx = [], []
    for p in ijk:
        leaf = leaf_of.get(tuple(int(c) & ~7 for c in p))
        b = (int(p[0]) & 7) * 64 + (int(p[1]) & 7) * 8 + (int(p[2]) & 7)
        if leaf is None:
            vals.append(np.asarray(grid.background, np.float64).reshape(comps))
            idx.append(-1)
            continue
        if values is not None:
            vals.append(np.asarray(values[leaf * 512 + b], np.float64).reshape(comps))
        if grid.grid_type == V.ON_INDEX:
            idx.append(int(rank[leaf, b]) if bits[leaf, b] else -1)
        else:
            idx.append(leaf * 512 + b)
    return (np.array(vals) if vals else None), np.array(idx)


def query_points(rng, origins, k=400):
    inside = origins[rng.integers(0, len(origins), k)] + rng.integers(0, 8, size=(k, 3))
    outside = rng.integers(-3000, 3000, size=(k // 4, 3))
    return np.concatenate([inside, outside]).astype(np.int32)


def assert_same_grid(a, b):
    assert a.grid_type == b.grid_type and a.name == b.name
    np.testing.assert_array_equal(a.origins, b.origins)
    np.testing.assert_array_equal(a.masks, b.masks)
    if a.values is None:
        assert b.values is None
    else:
        np.testing.assert_array_equal(a.values, b.values)
    np.testing.assert_array_equal(a.background, b.background)
    np.testing.assert_allclose(a.matrix, b.matrix, rtol=0, atol=0)
    np.testing.assert_allclose(a.translation, b.translation, rtol=0, atol=0)


# ---------------------------------------------------------------------------------------------
# pure parts: NanoVDB round trips


@pytest.mark.parametrize("grid_type", [1, 2, 4, 5, 6, 7, 10, 17, 18, V.INDEX, V.ON_INDEX])
@pytest.mark.parametrize("codec", ["none", "zip"])
def test_nanovdb_round_trip(rng, grid_type, codec):
    grid = random_grid(rng, grid_type)
    data = V.write_file([grid], codec)
    (back,) = V.parse_file(data)
    assert_same_grid(grid, back)
    assert back.grid_index == 0 and back.grid_count == 1
    assert back.active_count() == grid.active_count()
    raw = V.write_grid(grid)
    assert len(raw) == V.grid_byte_size(grid) and len(raw) % 32 == 0
    assert_same_grid(grid, V.parse_grids(raw)[0])


def test_nanovdb_multi_grid_and_blind_data(rng):
    grids = [random_grid(rng, t, n=10) for t in (1, V.ON_INDEX, 6)]
    payload = rng.integers(0, 255, size=37, dtype=np.uint8).tobytes()
    grids[1].blind = [V.BlindData("feature", 37, 1, 0, 4, 0, payload)]
    for codec in ("none", "zip"):
        back = V.parse_file(V.write_file(grids, codec))
        assert len(back) == 3
        for i, (a, b) in enumerate(zip(grids, back)):
            assert_same_grid(a, b)
            assert (b.grid_index, b.grid_count) == (i, 3)
        assert back[1].blind == grids[1].blind
    raw = b"".join(V.write_grid(g, i, 3) for i, g in enumerate(grids))
    assert [g.name for g in V.parse_grids(raw)] == [g.name for g in grids]


def test_onindex_leaf_offsets_give_ranks(rng):
    """The OnIndex leaves' first offset and 9-bit prefix sums decode to each active voxel's
    rank + 1 (NanoVDB's index of a voxel; 0 is the background)."""
    grid = random_grid(rng, V.ON_INDEX, n=20)
    raw = np.frombuffer(V.write_grid(grid), np.uint8)
    leaf_begin = V._GRID_SIZE + struct.unpack_from("<Q", raw, V._GRID_SIZE)[0]
    bits = V._mask_bits(grid.masks)
    rank = np.cumsum(bits.ravel()).reshape(bits.shape) - 1
    for leaf in range(grid.leaf_count):
        at = leaf_begin + leaf * 96
        offset, prefix = struct.unpack_from("<QQ", raw, at + 80)
        for b in np.nonzero(bits[leaf])[0][::7]:
            word, bit = int(b) // 64, int(b) % 64
            within = bin(int(grid.masks[leaf, word]) & ((1 << bit) - 1)).count("1")
            before = (prefix >> (9 * (word - 1))) & 511 if word else 0
            assert offset + before + within == rank[leaf, b] + 1


def test_internal_tiles_expand_into_leaves(rng):
    """A lower-node tile whose value differs from the background becomes one leaf (all voxels
    that value, active when the tile is); tiles equal to the background are dropped."""
    grid = random_grid(rng, 1, n=3, span=8)
    raw = bytearray(V.write_grid(grid))
    tree = V._GRID_SIZE
    lower = tree + struct.unpack_from("<Q", raw, tree + 8)[0]
    lower_origin = np.asarray(struct.unpack_from("<3i", raw, lower)) & ~127  # bbox min of lower 0
    child = np.unpackbits(np.frombuffer(bytes(raw[lower + V._LOWER_CHILD_MASK:lower + V._LOWER_CHILD_MASK + 512]),
                                        np.uint8), bitorder="little")
    entry = int(np.nonzero(child == 0)[0][rng.integers(0, 100)])
    tile_value = np.float32(rng.normal() + 20.0)
    struct.pack_into("<f", raw, lower + 1088 + entry * 8, tile_value)
    word, bit = entry // 32, entry % 32
    mask_at = lower + V._NODE_VALUE_MASK + 4 * word
    struct.pack_into("<I", raw, mask_at, struct.unpack_from("<I", raw, mask_at)[0] | (1 << bit))
    (back,) = V.parse_grids(bytes(raw))
    assert back.leaf_count == grid.leaf_count + 1
    np.testing.assert_array_equal(back.origins[:grid.leaf_count], grid.origins)
    expected_origin = lower_origin + 8 * np.array([entry >> 8, (entry >> 4) & 15, entry & 15])
    np.testing.assert_array_equal(back.origins[-1], expected_origin)
    assert np.all(back.masks[-1] == np.uint64(2**64 - 1))
    assert np.all(back.values[-512:] == tile_value)


def test_tile_expansion_limit(rng):
    """An upper-node tile (4096 leaves each) over the limit is a clear error, not a huge
    allocation."""
    grid = random_grid(rng, 1, n=2, span=8)
    raw = bytearray(V.write_grid(grid))
    tree = V._GRID_SIZE
    upper = tree + struct.unpack_from("<Q", raw, tree + 16)[0]
    child = np.unpackbits(np.frombuffer(bytes(raw[upper + V._UPPER_CHILD_MASK:upper + V._UPPER_CHILD_MASK + 4096]),
                                        np.uint8), bitorder="little")
    for entry in np.nonzero(child == 0)[0][:17]:
        struct.pack_into("<f", raw, upper + 8256 + int(entry) * 8, 1.0e3)
    with pytest.raises(RuntimeError, match="tiles"):
        V.parse_grids(bytes(raw))


# ---------------------------------------------------------------------------------------------
# pure parts: hostile buffers


def _fast_error(fn, match=None):
    start = time.perf_counter()
    with pytest.raises(RuntimeError, match=match):
        fn()
    assert time.perf_counter() - start < 2.0


def test_hostile_files_fail_clearly(rng):
    grid = random_grid(rng, 1, n=8)
    data = V.write_file([grid])
    _fast_error(lambda: V.parse_file(b"\0" * 15))
    _fast_error(lambda: V.parse_file(b"XXXXXXXX" + data[8:]), "NanoVDB signature not found")
    bad_version = bytearray(data)
    struct.pack_into("<I", bad_version, 8, 31 << 21)
    _fast_error(lambda: V.parse_file(bytes(bad_version)), "version")
    for cut in sorted(set(rng.integers(1, len(data) - 1, 40).tolist()) | {16, 100, 192, 16 + 176 + 20}):
        _fast_error(lambda: V.parse_file(data[:cut]))
    blosc = bytearray(data)
    struct.pack_into("<H", blosc, 14, 2)
    _fast_error(lambda: V.parse_file(bytes(blosc)), "blosc")
    zipped = bytearray(V.write_file([grid], "zip"))
    zipped[-20:] = b"\0" * 20
    _fast_error(lambda: V.parse_file(bytes(zipped)))


def test_hostile_grids_fail_clearly(rng):
    grid = random_grid(rng, 6, n=8)
    raw = V.write_grid(grid)
    tree = V._GRID_SIZE

    def patched(offset, fmt, value):
        out = bytearray(raw)
        struct.pack_into(fmt, out, offset, value)
        return bytes(out)

    _fast_error(lambda: V.parse_grids(patched(0, "<Q", 0x1234)), "signature")
    _fast_error(lambda: V.parse_grids(patched(32, "<Q", len(raw) * 4)), "truncated or corrupt")
    _fast_error(lambda: V.parse_grids(patched(tree + 32, "<I", 0xFFFFFFFF)), "leaf nodes")
    _fast_error(lambda: V.parse_grids(patched(tree + 32, "<I", grid.leaf_count + 1)), "leaf nodes")
    _fast_error(lambda: V.parse_grids(patched(tree, "<Q", 2**62)), "leaf nodes")
    _fast_error(lambda: V.parse_grids(patched(tree + 40, "<I", 0xFFFFFFF)), "upper nodes")
    _fast_error(lambda: V.parse_grids(patched(648, "<I", 0xFFFFFFFF)), "blind metadata")
    _fast_error(lambda: V.parse_grids(patched(648, "<I", 1)), "blind metadata")
    negative = bytearray(patched(648, "<I", 1))
    struct.pack_into("<q", negative, 640, -5)
    _fast_error(lambda: V.parse_grids(bytes(negative)), "blind metadata")
    _fast_error(lambda: V.parse_grids(patched(636, "<I", 9)), "'Half'")
    _fast_error(lambda: V.parse_grids(patched(636, "<I", 13)), "'Float4'")
    _fast_error(lambda: V.parse_grids(patched(636, "<I", 999)), "not supported")
    _fast_error(lambda: V.parse_grids(raw[:700]))
    _fast_error(lambda: V.parse_grids(raw[:40] + b"A" * 256 + raw[296:]), "NUL")
    duplicate = bytearray(raw)
    leaf = tree + struct.unpack_from("<Q", raw, tree)[0]
    duplicate[leaf + 6272:leaf + 6272 + 12] = duplicate[leaf:leaf + 12]
    _fast_error(lambda: V.parse_grids(bytes(duplicate)), "same origin")


def test_random_corruption_never_escapes_as_other_errors(rng):
    """Flipping random bytes of a grid either parses or raises RuntimeError (never an
    IndexError, struct.error, ValueError or MemoryError from deep inside)."""
    raw = bytearray(V.write_grid(random_grid(rng, 1, n=6)))
    for _ in range(200):
        hostile = bytearray(raw)
        for at in rng.integers(0, len(raw), 4):
            hostile[at] = int(rng.integers(0, 256))
        for at in rng.choice([32, 636, V._GRID_SIZE, V._GRID_SIZE + 8, V._GRID_SIZE + 24, V._GRID_SIZE + 32,
                              V._GRID_SIZE + 36, V._GRID_SIZE + 40, 640, 648], 2):
            hostile[int(at) + int(rng.integers(0, 4))] = int(rng.integers(0, 256))
        try:
            V.parse_grids(bytes(hostile))
        except RuntimeError:
            pass


# ---------------------------------------------------------------------------------------------
# pure parts: tiles and voxels


def test_voxel_coords_against_brute_force(rng):
    origins = random_origins(rng, 12)
    masks = random_masks(rng, len(origins), density=rng.uniform(0.05, 0.9))
    np.testing.assert_array_equal(V.voxel_coords(origins, masks, False), brute_voxels(origins, masks, False))
    np.testing.assert_array_equal(V.voxel_coords(origins, masks, True), brute_voxels(origins, masks, True))


def test_leaves_of_voxels_and_tiles_against_brute_force(rng):
    for span in (50, 3_000_000):   # packed keys, and the wide-range fallback
        points = rng.integers(-span, span, size=(500, 3))
        points = np.concatenate([points, points[:100]])       # duplicates merge
        origins, masks = V.leaves_of_voxels(points)
        expected_origins = sorted({tuple(int(c) & ~7 for c in p) for p in points})
        np.testing.assert_array_equal(origins, np.array(expected_origins, np.int32))
        np.testing.assert_array_equal(V.leaves_of_tiles(points), origins)
        expected_voxels = sorted({tuple(int(c) for c in p) for p in points})
        got = brute_voxels(origins, masks, True)
        assert sorted(map(tuple, got.tolist())) == expected_voxels


def test_world_to_index_rounds_to_nearest_voxel(rng):
    matrix = np.diag(rng.uniform(0.1, 2.0, 3))
    translation = rng.normal(size=3)
    ijk = rng.integers(-1000, 1000, size=(300, 3))
    jitter = rng.uniform(-0.49, 0.49, size=ijk.shape)
    world = (ijk + jitter) @ matrix.T + translation
    np.testing.assert_array_equal(V.world_to_index(world, matrix, translation), ijk)


def test_value_types_and_voxel_sizes():
    assert V.grid_type_of_value(1.5) == 1 and V.grid_type_of_value(3) == 4
    assert V.grid_type_of_value(wp.float64(2.0)) == 2 and V.grid_type_of_value(wp.int64(2)) == 5
    assert V.grid_type_of_value(wp.uint32(2)) == 10
    assert V.grid_type_of_value([1.0, 2.0, 3.0]) == 6 and V.grid_type_of_value((1, 2, 3, 4)) == 17
    assert V.grid_type_of_value(wp.vec3d(1, 2, 3)) == 7 and V.grid_type_of_value(wp.vec4d()) == 18
    assert V.grid_type_of_value(np.array([1.0, 2.0, 3.0])) == 6
    for bad in (True, wp.int16(1), wp.vec2(1, 2), wp.mat22()):
        with pytest.raises(TypeError, match="Unsupported bg_value type for volume allocation"):
            V.grid_type_of_value(bad)
    assert wp.Volume._normalize_voxel_size(2) == (2.0, 2.0, 2.0)
    assert wp.Volume._normalize_voxel_size([1, 2, 3]) == (1.0, 2.0, 3.0)
    with pytest.raises(ValueError, match="3-element"):
        wp.Volume._normalize_voxel_size([1, 2])
    with pytest.raises(ValueError, match="finite and positive"):
        wp.Volume._normalize_voxel_size((1.0, 0.0, 1.0))
    with pytest.raises(ValueError, match="finite and positive"):
        wp.Volume._normalize_voxel_size(float("nan"))
    with pytest.raises(TypeError, match="voxel_size must be a numeric scalar"):
        wp.Volume._normalize_voxel_size("1")


def test_million_voxel_grid_is_fast(rng):
    """2048 leaves (1M voxels) of float32: written and parsed in well under a second each."""
    origins = np.stack(np.meshgrid(*[np.arange(s) * 8 for s in (16, 16, 8)], indexing="ij"), -1).reshape(-1, 3)
    grid = V.GridContent(1, origins, random_masks(rng, len(origins)), rng.random((len(origins) * 512, 1),
                                                                                np.float32),
                         0.0, np.eye(3), np.zeros(3))
    start = time.perf_counter()
    data = V.write_file([grid])
    write_s = time.perf_counter() - start
    start = time.perf_counter()
    (back,) = V.parse_file(data)
    coords = V.voxel_coords(back.origins, back.masks, True)
    read_s = time.perf_counter() - start
    assert coords.shape[0] == grid.active_count()
    assert write_s < 1.0 and read_s < 1.0, (write_s, read_s)


# ---------------------------------------------------------------------------------------------
# pure parts: Warp's test assets


def _asset(name):
    path = os.path.join(ASSETS, name)
    if not os.path.exists(path):
        pytest.skip(f"{path} not present")
    with open(path, "rb") as f:
        return f.read()


@pytest.mark.parametrize("name, grid_type", [("test_grid.nvdb", 1), ("test_int32_grid.nvdb", 4),
                                             ("test_vec_grid.nvdb", 6)])
def test_warp_assets(name, grid_type):
    (grid,) = V.parse_file(_asset(name))
    assert grid.grid_type == grid_type
    np.testing.assert_allclose(grid.voxel_size, 0.25)
    ijk = V.voxel_coords(grid.origins, grid.masks, True)
    assert ijk.min() == -10 and ijk.max() == 10 and len(ijk) == 21 ** 3
    leaf, bit = np.nonzero(V._mask_bits(grid.masks))
    values = grid.values.reshape(grid.leaf_count, 512, -1)[leaf, bit].astype(np.float64)
    i, j, k = ijk.T.astype(np.float64)
    if grid_type == 6:
        expected = np.stack([i + 2 * j + 3 * k, 4 * i + 5 * j + 6 * k, 7 * i + 8 * j + 9 * k], axis=1)
    else:
        expected = (i * j * k)[:, None]
    np.testing.assert_array_equal(values, expected)


def test_warp_index_asset_has_two_grids_and_blind_data():
    grids = V.parse_file(_asset("test_index_grid.nvdb"))
    assert [g.name for g in grids] == ["grid-0", "grid-1"]
    assert all(g.grid_type == V.ON_INDEX for g in grids)
    data = np.frombuffer(grids[0].blind[0].data, np.uint64)
    assert list(data[:4]) == [3, grids[0].active_count(), 2, 3]
    assert [V.grid_byte_size(g) for g in grids] == [2132896, 2437856]


# ---------------------------------------------------------------------------------------------
# end to end through the daemon


@pytest.fixture
def volumes(device):
    try:
        wp.Volume.allocate((0, 0, 0), (7, 7, 7), voxel_size=1.0, device=device)
    except Exception as err:  # noqa: BLE001 - the daemon's answer decides
        if "unknown operation" in str(err):
            pytest.skip(f"this weftd has no CREATE_VOLUME: {err}")
        raise


@wp.kernel
def lookup_f(volume: wp.uint64, ijk: wp.array2d(dtype=wp.int32), out: wp.array(dtype=float),
             index: wp.array(dtype=int)):
    t = wp.tid()
    out[t] = wp.volume_lookup_f(volume, ijk[t, 0], ijk[t, 1], ijk[t, 2])
    index[t] = wp.volume_lookup_index(volume, ijk[t, 0], ijk[t, 1], ijk[t, 2])


@wp.kernel
def lookup_v(volume: wp.uint64, ijk: wp.array2d(dtype=wp.int32), out: wp.array(dtype=wp.vec3)):
    t = wp.tid()
    out[t] = wp.volume_lookup_v(volume, ijk[t, 0], ijk[t, 1], ijk[t, 2])


@wp.kernel
def lookup_i(volume: wp.uint64, ijk: wp.array2d(dtype=wp.int32), out: wp.array(dtype=int)):
    t = wp.tid()
    out[t] = wp.volume_lookup_i(volume, ijk[t, 0], ijk[t, 1], ijk[t, 2])


@wp.kernel
def lookup_d(volume: wp.uint64, ijk: wp.array2d(dtype=wp.int32), out: wp.array(dtype=wp.float64)):
    t = wp.tid()
    out[t] = wp.volume_lookup(volume, ijk[t, 0], ijk[t, 1], ijk[t, 2], dtype=wp.float64)


@wp.kernel
def lookup_index(volume: wp.uint64, ijk: wp.array2d(dtype=wp.int32), index: wp.array(dtype=int),
                 count: wp.array(dtype=int)):
    t = wp.tid()
    index[t] = wp.volume_lookup_index(volume, ijk[t, 0], ijk[t, 1], ijk[t, 2])
    if t == 0:
        count[0] = wp.volume_voxel_count(volume)


@wp.kernel
def store_f(volume: wp.uint64, ijk: wp.array2d(dtype=wp.int32), values: wp.array(dtype=float)):
    t = wp.tid()
    wp.volume_store_f(volume, ijk[t, 0], ijk[t, 1], ijk[t, 2], values[t])


@wp.kernel
def sample_world(volume: wp.uint64, xyz: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    t = wp.tid()
    uvw = wp.volume_world_to_index(volume, xyz[t])
    out[t] = wp.volume_sample_f(volume, uvw, wp.Volume.LINEAR)


@wp.kernel
def transforms(volume: wp.uint64, ijk: wp.array(dtype=wp.vec3), world: wp.array(dtype=wp.vec3),
               back: wp.array(dtype=wp.vec3), world_dir: wp.array(dtype=wp.vec3)):
    t = wp.tid()
    world[t] = wp.volume_index_to_world(volume, ijk[t])
    back[t] = wp.volume_world_to_index(volume, world[t])
    world_dir[t] = wp.volume_index_to_world_dir(volume, ijk[t])


def _ijk_array(points):
    return wp.array(np.ascontiguousarray(points, np.int32), dtype=wp.int32, device=DEV)


def _load(grid):
    return wp.Volume.load_from_nvdb(V.write_file([grid]), device=DEV)


@pytest.mark.usefixtures("volumes")
def test_e2e_lookups_match_reference(rng):
    cases = [(1, lookup_f, wp.float32), (6, lookup_v, wp.vec3), (4, lookup_i, wp.int32), (2, lookup_d, wp.float64)]
    for grid_type, kernel, dtype in cases:
        grid = random_grid(rng, grid_type, n=12)
        volume = _load(grid)
        ijk = query_points(rng, grid.origins)
        out = wp.zeros(len(ijk), dtype=dtype, device=DEV)
        inputs = [volume.id, _ijk_array(ijk), out]
        index = wp.zeros(len(ijk), dtype=int, device=DEV)
        if kernel is lookup_f:
            inputs.append(index)
        wp.launch(kernel, dim=len(ijk), inputs=inputs, device=DEV)
        expected, expected_index = brute_lookup(grid, grid.values, ijk)
        got = np.asarray(out.numpy(), np.float64).reshape(expected.shape)
        np.testing.assert_array_equal(got, expected.astype(grid.layout.scalar).astype(np.float64))
        if kernel is lookup_f:
            np.testing.assert_array_equal(index.numpy(), expected_index)
        assert volume.dtype is {1: wp.float32, 6: wp.vec3f, 4: wp.int32, 2: wp.float64}[grid_type]


@pytest.mark.usefixtures("volumes")
def test_e2e_onindex_lookup_index_and_voxel_count(rng):
    points = rng.integers(-300, 300, size=(700, 3)).astype(np.int32)
    volume = wp.Volume.allocate_by_voxels(_ijk_array(points), voxel_size=0.5, device=DEV)
    assert volume.is_index and volume.dtype is None
    origins, masks = V.leaves_of_voxels(points)
    grid = V.GridContent(V.ON_INDEX, origins, masks, None, 0, np.eye(3), np.zeros(3))
    np.testing.assert_array_equal(volume.get_tiles().numpy(), origins)
    voxels = volume.get_voxels().numpy()
    np.testing.assert_array_equal(voxels, brute_voxels(origins, masks, True))
    assert volume.get_voxel_count() == len(np.unique(points, axis=0)) == len(voxels)
    ijk = np.concatenate([points, query_points(rng, origins)])
    index = wp.zeros(len(ijk), dtype=int, device=DEV)
    count = wp.zeros(1, dtype=int, device=DEV)
    wp.launch(lookup_index, dim=len(ijk), inputs=[volume.id, _ijk_array(ijk), index, count], device=DEV)
    np.testing.assert_array_equal(index.numpy(), brute_lookup(grid, None, ijk)[1])
    assert count.numpy()[0] == volume.get_voxel_count()
    np.testing.assert_array_equal(voxels[index.numpy()[:len(points)]], points)


@pytest.mark.usefixtures("volumes")
def test_e2e_store_then_save(rng, tmp_path):
    tiles = rng.integers(-100, 100, size=(40, 3)).astype(np.int32)
    bg = float(rng.normal() - 10.0)
    volume = wp.Volume.allocate_by_tiles(_ijk_array(tiles), voxel_size=0.3, bg_value=bg, device=DEV)
    origins = V.leaves_of_tiles(tiles)
    np.testing.assert_array_equal(volume.get_tiles().numpy(), origins)
    assert volume.get_voxel_count() == 512 * len(origins)
    ijk = query_points(rng, origins, k=300)
    ijk = np.unique(ijk, axis=0)
    values = rng.normal(size=len(ijk)).astype(np.float32)
    wp.launch(store_f, dim=len(ijk), inputs=[volume.id, _ijk_array(ijk), wp.array(values, device=DEV)], device=DEV)
    path = str(tmp_path / "stored.nvdb")
    volume.save_to_nvdb(path, codec="zip")
    with open(path, "rb") as f:
        (saved,) = V.parse_file(f.read())
    reference = np.full((len(origins) * 512, 1), bg, np.float32)
    leaf_of = {tuple(o): i for i, o in enumerate(origins.tolist())}
    for p, v in zip(ijk.tolist(), values):
        leaf = leaf_of.get(tuple(c & ~7 for c in p))
        if leaf is not None:
            reference[leaf * 512 + (p[0] & 7) * 64 + (p[1] & 7) * 8 + (p[2] & 7)] = v
    np.testing.assert_array_equal(saved.values, reference)
    np.testing.assert_array_equal(volume.values.numpy().reshape(-1, 1), reference)
    again = wp.Volume(volume.array())
    out = wp.zeros(len(ijk), dtype=float, device=DEV)
    index = wp.zeros(len(ijk), dtype=int, device=DEV)
    wp.launch(lookup_f, dim=len(ijk), inputs=[again.id, _ijk_array(ijk), out, index], device=DEV)
    np.testing.assert_array_equal(out.numpy(), brute_lookup(saved, saved.values, ijk)[0].ravel().astype(np.float32))


@pytest.mark.usefixtures("volumes")
def test_e2e_linear_sample_in_world_space(rng):
    grid = random_grid(rng, 1, n=10, span=6)
    grid.matrix = np.diag(rng.uniform(0.5, 1.5, 3))
    volume = _load(grid)
    leaf = rng.integers(0, grid.leaf_count, 500)
    ijk = grid.origins[leaf] + rng.uniform(0.5, 6.5, size=(500, 3))
    xyz = (ijk @ grid.matrix.T + grid.translation).astype(np.float32)
    uvw = (xyz.astype(np.float64) - grid.translation) @ np.linalg.inv(grid.matrix).T
    out = wp.zeros(len(xyz), dtype=float, device=DEV)
    wp.launch(sample_world, dim=len(xyz), inputs=[volume.id, wp.array(xyz, dtype=wp.vec3, device=DEV), out],
              device=DEV)
    base = np.floor(uvw).astype(np.int64)
    frac = uvw - base
    reference = np.zeros(len(uvw))
    for corner in np.stack(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij"), -1).reshape(-1, 3):
        weight = np.prod(np.where(corner == 1, frac, 1.0 - frac), axis=1)
        values, _ = brute_lookup(grid, grid.values, base + corner)
        reference += weight * values[:, 0]
    np.testing.assert_allclose(out.numpy(), reference, rtol=0, atol=LIN_TOL)


@pytest.mark.usefixtures("volumes")
def test_e2e_index_world_transforms(rng):
    matrix = rng.normal(size=(3, 3)) + 2.0 * np.eye(3)
    translation = rng.normal(size=3) * 10.0
    tiles = rng.integers(-50, 50, size=(5, 3)).astype(np.int32)
    volume = wp.Volume.allocate_by_tiles(_ijk_array(tiles), transform=wp.mat33(*matrix.ravel()),
                                         translation=translation, device=DEV)
    matrix = matrix.astype(np.float32).astype(np.float64)
    info = volume.get_grid_info()
    np.testing.assert_allclose(np.array(info.transform_matrix).reshape(3, 3), matrix, atol=1e-6)
    np.testing.assert_allclose(np.array(info.translation), translation, atol=1e-5)
    ijk = rng.uniform(-100, 100, size=(200, 3))
    world, back, world_dir = (wp.zeros(200, dtype=wp.vec3, device=DEV) for _ in range(3))
    wp.launch(transforms, dim=200, inputs=[volume.id, wp.array(ijk.astype(np.float32), dtype=wp.vec3, device=DEV),
                                            world, back, world_dir], device=DEV)
    ijk32 = ijk.astype(np.float32).astype(np.float64)
    scale = 1e-5 * 1000
    np.testing.assert_allclose(world.numpy(), ijk32 @ matrix.T + translation, atol=scale)
    np.testing.assert_allclose(world_dir.numpy(), ijk32 @ matrix.T, atol=scale)
    np.testing.assert_allclose(back.numpy(), ijk32, atol=scale)


@pytest.mark.usefixtures("volumes")
def test_e2e_load_from_numpy(rng):
    dense = rng.normal(size=(13, 9, 20)).astype(np.float32)
    volume = wp.Volume.load_from_numpy(dense, min_world=(1.0, -2.0, 0.5), voxel_size=0.5, bg_value=-7.0, device=DEV)
    assert volume.get_tile_count() == 2 * 2 * 3
    np.testing.assert_allclose(volume.get_voxel_size(), (0.5, 0.5, 0.5))
    ijk = np.stack(np.meshgrid(*[np.arange(-2, s + 3) for s in dense.shape], indexing="ij"), -1).reshape(-1, 3)
    out = wp.zeros(len(ijk), dtype=float, device=DEV)
    index = wp.zeros(len(ijk), dtype=int, device=DEV)
    wp.launch(lookup_f, dim=len(ijk), inputs=[volume.id, _ijk_array(ijk), out, index], device=DEV)
    inside = np.all((ijk >= 0) & (ijk < dense.shape), axis=1)
    expected = np.full(len(ijk), -7.0, np.float32)
    expected[inside] = dense[tuple(ijk[inside].T)]
    np.testing.assert_array_equal(out.numpy(), expected)
    vec = rng.normal(size=(5, 6, 7, 3)).astype(np.float32)
    volume = wp.Volume.load_from_numpy(vec, bg_value=(1.0, 2.0, 3.0), device=DEV)
    assert volume.dtype is wp.vec3f
    ints = rng.integers(-50, 50, size=(4, 4, 4)).astype(np.int32)
    volume = wp.Volume.load_from_numpy(ints, bg_value=0, device=DEV)
    assert volume.dtype is wp.int32
    out = wp.zeros(64, dtype=int, device=DEV)
    ijk = np.stack(np.meshgrid(*[np.arange(4)] * 3, indexing="ij"), -1).reshape(-1, 3)
    wp.launch(lookup_i, dim=64, inputs=[volume.id, _ijk_array(ijk), out], device=DEV)
    np.testing.assert_array_equal(out.numpy(), ints.ravel())


@pytest.mark.usefixtures("volumes")
def test_e2e_allocate_introspection_and_errors(rng, tmp_path):
    volume = wp.Volume.allocate((-9, 0, 3), (20, 7, 30), voxel_size=(0.5, 1.0, 2.0), bg_value=wp.vec3d(1, 2, 3),
                                device=DEV)
    assert volume.dtype is wp.vec3d and not volume.is_index and not volume.is_rebuildable
    tiles = volume.get_tiles().numpy()
    expected = [(x, y, z) for x in range(-16, 24, 8) for y in (0,) for z in range(0, 32, 8)]
    assert list(map(tuple, tiles.tolist())) == expected
    assert volume.get_voxel_size() == (0.5, 1.0, 2.0)
    stats = volume.get_active_stats()
    assert stats == (512 * len(expected), len(expected), 2, 2)   # x spans the lower nodes at -128 and 0
    out = wp.empty(shape=(len(expected) + 3,), dtype=wp.vec3i, device=DEV)
    assert volume.get_tiles(out=out) is out
    np.testing.assert_array_equal(out.numpy()[:len(expected)], tiles)
    with pytest.raises(RuntimeError, match="at least"):
        volume.get_tiles(out=wp.empty(shape=(1, 3), dtype=wp.int32, device=DEV))
    info = volume.get_grid_info()
    assert (info.name, info.grid_index, info.grid_count, info.type_str) == ("", 0, 1, "Vec3d")
    assert info.size_in_bytes == len(np.frombuffer(volume.array().numpy(), np.uint8))
    assert volume.get_rebuild_info() == wp.Volume.RebuildInfo(None, 0, 0, 0, 0)
    assert volume.get_feature_array_count() == 0 and volume.load_next_grid() is None
    with pytest.raises(TypeError, match="Unsupported bg_value type"):
        wp.Volume.allocate((0, 0, 0), (7, 7, 7), voxel_size=1.0, bg_value=wp.vec2(1, 2), device=DEV)
    with pytest.raises(ValueError, match="Either 'voxel_size' or 'transform'"):
        wp.Volume.allocate_by_tiles(_ijk_array(tiles), device=DEV)
    with pytest.raises(ValueError, match="Only one of"):
        wp.Volume.allocate_by_tiles(_ijk_array(tiles), voxel_size=1.0, transform=np.eye(3), device=DEV)
    with pytest.raises(RuntimeError, match="tile_points must be contiguous"):
        wp.Volume.allocate_by_tiles(wp.zeros(4, dtype=wp.float64, device=DEV), voxel_size=1.0, device=DEV)
    with pytest.raises(RuntimeError, match="Unsupported codec"):
        volume.save_to_nvdb(str(tmp_path / "x.nvdb"), codec="lz4")


@pytest.mark.usefixtures("volumes")
def test_e2e_world_space_tile_points_and_index_allocation(rng):
    voxel_size = 0.25
    points = rng.uniform(-20, 20, size=(300, 3)).astype(np.float32)
    volume = wp.Volume.allocate_by_tiles(wp.array(points, dtype=wp.vec3, device=DEV), voxel_size=voxel_size,
                                         bg_value=None, device=DEV)
    assert volume.is_index and volume.get_grid_info().type_str == "OnIndex"
    nearest = np.floor(points.astype(np.float64) / voxel_size + 0.5).astype(np.int64)
    np.testing.assert_array_equal(volume.get_tiles().numpy(), V.leaves_of_tiles(nearest))
    assert volume.get_voxel_count() == 512 * volume.get_tile_count()


@pytest.mark.usefixtures("volumes")
def test_e2e_warp_assets_and_next_grid():
    data = _asset("test_grid.nvdb")
    volume = wp.Volume.load_from_nvdb(data, device=DEV)
    ijk = np.stack(np.meshgrid(*[np.arange(-11, 12)] * 3, indexing="ij"), -1).reshape(-1, 3)
    out = wp.zeros(len(ijk), dtype=float, device=DEV)
    index = wp.zeros(len(ijk), dtype=int, device=DEV)
    wp.launch(lookup_f, dim=len(ijk), inputs=[volume.id, _ijk_array(ijk), out, index], device=DEV)
    inside = np.all(np.abs(ijk) <= 10, axis=1)
    got = out.numpy()
    np.testing.assert_array_equal(got[inside], np.prod(ijk[inside], axis=1).astype(np.float32))
    assert volume.get_voxel_size() == (0.25, 0.25, 0.25)
    first = wp.Volume.load_from_nvdb(_asset("test_index_grid.nvdb"), device=DEV)
    assert first.get_feature_array_count() == 1
    feature = first.feature_array(0, dtype=wp.uint64).numpy()
    assert list(feature[:4]) == [3, first.get_voxel_count(), 2, 3]
    assert first.get_feature_array_info(0).value_size == 1
    second = first.load_next_grid()
    assert second.get_grid_info().grid_index == 1 and second.load_next_grid() is None
    assert second.get_voxel_count() != first.get_voxel_count()
    with pytest.raises(RuntimeError, match="aliased"):
        second.save_to_nvdb("/dev/null")


def test_zip_chunk_layout(rng):
    """A zip file: header, metadata + name per grid, then per grid a u64 size and a zlib stream
    of the grid."""
    grid = random_grid(rng, 4, n=4)
    data = V.write_file([grid], "zip")
    name_size = struct.unpack_from("<I", data, 16 + 136)[0]
    at = 16 + 176 + name_size
    size = struct.unpack_from("<Q", data, at)[0]
    assert zlib.decompress(data[at + 8:at + 8 + size]) == V.write_grid(grid)
