"""Marching cubes example: a field of smoothly blended spheres (a signed-distance-like function,
negative inside) is sampled on a grid by a kernel, its zero level set is extracted with
wp.geometry.IsoSurfaceMarchingCubes, the triangles become a wp.Mesh, and a kernel ray-casts that
mesh into a shaded picture written as out/iso_surface/iso_surface.png. Runs on the daemon's
preferred device (a GPU if it has one, else the CPU).

Checks printed at the end: the mesh is closed and consistently wound (each triangle side is
shared with exactly one other triangle, the other way round), and the volume it encloses
against a float64 Monte Carlo estimate of the volume where the field is negative.

    WEFT_DAEMON=build/bin/weftd python clients/python/examples/iso_surface.py [grid size]
"""
from __future__ import annotations

import collections
import sys
import time
from pathlib import Path

import numpy as np

import weft as wp
import weft.geometry

sys.path.insert(0, str(Path(__file__).resolve().parent))
from demo import write_png  # noqa: E402

CENTERS = np.array([[-0.35, -0.1, 0.0], [0.35, 0.05, 0.1], [0.0, 0.35, -0.2], [0.05, -0.3, 0.3]])
RADII = np.array([0.38, 0.33, 0.27, 0.22])
BLEND = 0.12
IMAGE = 512


@wp.func
def blob_field(p: wp.vec3, centers: wp.array[wp.vec3], radii: wp.array[float]):
    """Smooth minimum of the spheres' distances (polynomial blend of width BLEND)."""
    d = wp.length(p - centers[0]) - radii[0]
    for s in range(1, centers.shape[0]):
        e = wp.length(p - centers[s]) - radii[s]
        h = wp.clamp(0.5 + 0.5 * (e - d) / 0.12, 0.0, 1.0)
        d = wp.lerp(e, d, h) - 0.12 * h * (1.0 - h)
    return d


@wp.kernel
def sample(field: wp.array3d[float], centers: wp.array[wp.vec3], radii: wp.array[float]):
    i, j, k = wp.tid()
    n = float(field.shape[0] - 1)
    p = wp.vec3(2.0 * float(i) / n - 1.0, 2.0 * float(j) / n - 1.0, 2.0 * float(k) / n - 1.0)
    field[i, j, k] = blob_field(p, centers, radii)


@wp.kernel
def render(mesh: wp.uint64, eye: wp.vec3, light: wp.vec3, image: wp.array3d[float]):
    y, x = wp.tid()
    size = float(image.shape[0])
    u = 2.0 * (float(x) + 0.5) / size - 1.0
    v = 1.0 - 2.0 * (float(y) + 0.5) / size
    forward = wp.normalize(-eye)
    right = wp.normalize(wp.cross(forward, wp.vec3(0.0, 1.0, 0.0)))
    up = wp.cross(right, forward)
    ray = wp.normalize(forward + 0.36 * (u * right + v * up))
    hit = wp.mesh_query_ray(mesh, eye, ray, 100.0)
    color = wp.vec3(0.06, 0.06, 0.09) * (1.0 + 0.5 * v)
    if hit.result:
        n = wp.normalize(hit.normal)
        diffuse = wp.max(wp.dot(n, light), 0.0)
        back = wp.max(wp.dot(n, -ray), 0.0)
        color = wp.vec3(0.85, 0.55, 0.3) * (0.08 + 0.9 * diffuse * diffuse) + wp.vec3(0.1, 0.15, 0.25) * back
    image[y, x, 0] = color[0]
    image[y, x, 1] = color[1]
    image[y, x, 2] = color[2]


def monte_carlo_volume(samples: int, rng) -> float:
    """float64 volume of {field < 0} in [-1, 1]^3."""
    p = rng.uniform(-1.0, 1.0, (samples, 3))
    d = np.linalg.norm(p - CENTERS[0], axis=1) - RADII[0]
    for c, r in zip(CENTERS[1:], RADII[1:]):
        e = np.linalg.norm(p - c, axis=1) - r
        h = np.clip(0.5 + 0.5 * (e - d) / BLEND, 0.0, 1.0)
        d = e + (d - e) * h - BLEND * h * (1.0 - h)
    return 8.0 * float(np.mean(d < 0.0))


def main() -> int:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 96
    device = str(wp.get_preferred_device().alias)
    print(f"iso-surface of blended spheres on a {n}^3 grid, device {device}")
    centers = wp.array(CENTERS.astype(np.float32), dtype=wp.vec3, device=device)
    radii = wp.array(RADII.astype(np.float32), dtype=float, device=device)
    field = wp.empty((n, n, n), dtype=float, device=device)
    wp.launch(sample, dim=field.shape, inputs=[field, centers, radii], device=device)

    start = time.perf_counter()
    verts, indices = wp.geometry.IsoSurfaceMarchingCubes.extract(
        field, 0.0, lower=(-1.0, -1.0, -1.0), upper=(1.0, 1.0, 1.0))
    faces = indices.numpy().reshape(-1, 3)
    seconds = time.perf_counter() - start
    print(f"  marching cubes: {len(verts)} vertices, {len(faces)} triangles in {seconds * 1e3:.1f} ms")

    sides = collections.Counter((int(a), int(b)) for f in faces for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])))
    closed = all(c == 1 for c in sides.values()) and all(sides[(b, a)] == 1 for a, b in sides)
    p = verts.numpy().astype(np.float64)[faces]
    volume = float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0)
    reference = monte_carlo_volume(2_000_000, np.random.default_rng(7))
    print(f"  closed, consistently wound: {closed}")
    print(f"  enclosed volume {volume:.4f}, float64 Monte Carlo {reference:.4f} "
          f"(relative difference {abs(volume - reference) / reference:.2%})")

    mesh = wp.Mesh(points=verts, indices=indices)
    image = wp.empty((IMAGE, IMAGE, 3), dtype=float, device=device)
    eye = wp.vec3(1.6, 1.1, 2.4)
    light = wp.normalize(wp.vec3(0.5, 0.8, 0.6))
    wp.launch(render, dim=(IMAGE, IMAGE), inputs=[mesh.id, eye, light, image], device=device)
    rgb = (np.clip(image.numpy(), 0.0, 1.0) ** (1 / 2.2) * 255).astype(np.uint8)
    out = Path("out/iso_surface")
    out.mkdir(parents=True, exist_ok=True)
    write_png(out / "iso_surface.png", rgb)
    print(f"  wrote {out / 'iso_surface.png'}")
    return 0 if closed and abs(volume - reference) / reference < 0.02 else 1


if __name__ == "__main__":
    sys.exit(main())
