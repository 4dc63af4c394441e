"""weft demo (`make demo`): 200k particles fall under gravity into a box with a ground plane,
walls, restitution and drag, simulated by kernels in weftd on the best device present (a GPU
if the daemon has one, else the CPU). Every few steps a kernel splats the particles into an
image with atomics; frames are written as PNG files to out/demo/.

Checks printed at the end:
  * free fall: for the first steps (before any particle can reach the floor) every position
    must match the exact solution of the semi-implicit Euler recurrence, computed in float64
    by NumPy: x_n = x_0 + n dt v_0 + dt^2 g n (n + 1) / 2;
  * energy: total energy from an atomic_add reduction in a kernel against the float64 NumPy
    sum, and its balance (kinetic + potential is conserved to O(dt) in free fall; afterwards
    restitution and drag only remove energy).
"""
from __future__ import annotations

import os
import struct
import sys
import time
import zlib
from pathlib import Path

import numpy as np

import weft as wp

NUM_PARTICLES = 200_000
STEPS = 240
FREE_FALL_STEPS = 20
FRAME_EVERY = 10
DT = 1.0 / 120.0
GRAVITY = wp.constant(wp.vec3(0.0, -9.81, 0.0))
BOX = wp.constant(2.0)            # the box spans [-BOX, BOX] in x and z, the floor is y = 0
RESTITUTION = wp.constant(0.7)
DRAG = wp.constant(0.02)
IMAGE_SIZE = 384


@wp.kernel
def integrate(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), dt: float):
    tid = wp.tid()
    v1 = v[tid] + GRAVITY * dt
    x[tid] = x[tid] + v1 * dt
    v[tid] = v1


@wp.kernel
def collide(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), dt: float):
    tid = wp.tid()
    p = x[tid]
    u = v[tid] * (1.0 - DRAG * dt)
    if p[1] < 0.0:
        p = wp.vec3(p[0], -p[1] * RESTITUTION, p[2])
        u = wp.vec3(u[0] * 0.9, wp.abs(u[1]) * RESTITUTION, u[2] * 0.9)
    for axis in range(3):
        if axis != 1:
            if p[axis] > BOX:
                p[axis] = BOX - (p[axis] - BOX) * RESTITUTION
                u[axis] = -wp.abs(u[axis]) * RESTITUTION
            if p[axis] < -BOX:
                p[axis] = -BOX + (-BOX - p[axis]) * RESTITUTION
                u[axis] = wp.abs(u[axis]) * RESTITUTION
    x[tid] = p
    v[tid] = u


@wp.kernel
def energy(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), total: wp.array(dtype=float)):
    tid = wp.tid()
    e = 0.5 * wp.dot(v[tid], v[tid]) - wp.dot(GRAVITY, x[tid])
    wp.atomic_add(total, 0, e)


@wp.kernel
def splat(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), image: wp.array2d(dtype=float),
          speed: wp.array2d(dtype=float), size: int, scale: float):
    tid = wp.tid()
    p = x[tid]
    # side view: screen x from world x (plus a little z for depth), screen y from world y
    sx = int((p[0] + 0.35 * p[2] + BOX * 1.35) * scale)
    sy = size - 1 - int((p[1] + 0.1) * scale)
    if sx >= 0 and sx < size and sy >= 0 and sy < size:
        wp.atomic_add(image, sy, sx, 1.0)
        wp.atomic_add(speed, sy, sx, wp.length(v[tid]))


def write_png(path: Path, rgb: np.ndarray) -> None:
    """An 8-bit RGB PNG written with zlib and struct only."""
    height, width, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[row].tobytes() for row in range(height))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data +
                struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) +
                     chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))


def tone_map(counts: np.ndarray, speed_sum: np.ndarray, scale: float) -> np.ndarray:
    """Brightness from particle density, colour from mean speed (blue slow .. orange fast),
    with the box (floor and walls) drawn in grey."""
    level = np.log1p(counts) / np.log1p(max(counts.max(), 1.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        speed = np.where(counts > 0, speed_sum / np.maximum(counts, 1), 0.0)
    hot = np.clip(speed / 8.0, 0, 1)
    rgb = np.stack([0.25 + 0.75 * hot, 0.45 + 0.35 * hot, 1.0 - 0.8 * hot], axis=-1)
    rgb = rgb * (0.25 + 0.75 * level[..., None])
    rgb[counts == 0] = (0.05, 0.05, 0.08)
    size = counts.shape[0]
    floor = size - 1 - int(0.1 * scale)
    left, right = int((-2.0 + 2.0 * 1.35) * scale), int((2.0 + 2.0 * 1.35) * scale)
    rgb[floor:floor + 2, left:right] = (0.6, 0.6, 0.6)
    rgb[:floor, left:left + 2] = (0.35, 0.35, 0.35)
    rgb[:floor, min(right, size - 2):min(right, size - 2) + 2] = (0.35, 0.35, 0.35)
    return (np.clip(rgb, 0, 1) * 255).astype(np.uint8)


def pick_device() -> str:
    # The daemon's preferred device: its first GPU that can run kernels, else the CPU.
    return str(wp.get_preferred_device().alias)


def total_energy(x, v) -> tuple:
    """(kernel atomic_add reduction in float32, float64 NumPy reference)."""
    total = wp.zeros(1, dtype=float, device=x.device)
    wp.launch(energy, dim=NUM_PARTICLES, inputs=[x, v, total])
    xs = x.numpy().astype(np.float64)
    vs = v.numpy().astype(np.float64)
    reference = 0.5 * (vs * vs).sum() + 9.81 * xs[:, 1].sum()
    return float(total.numpy()[0]), float(reference)


def main() -> int:
    out_dir = Path(os.environ.get("WEFT_DEMO_OUT", Path.cwd() / "out" / "demo"))
    out_dir.mkdir(parents=True, exist_ok=True)
    wp.init()
    device = pick_device()
    rng = np.random.default_rng(7)
    n = NUM_PARTICLES
    # a block of particles high above the floor, with a sideways swirl
    x0 = np.stack([rng.uniform(-1.8, -0.6, n), rng.uniform(2.5, 5.5, n),
                   rng.uniform(-0.6, 0.6, n)], axis=1).astype(np.float32)
    v0 = np.stack([3.0 + 0.5 * rng.standard_normal(n), 0.5 * rng.standard_normal(n),
                   0.5 * rng.standard_normal(n)], axis=1).astype(np.float32)
    x = wp.array(x0, dtype=wp.vec3, device=device)
    v = wp.array(v0, dtype=wp.vec3, device=device)
    image = wp.zeros((IMAGE_SIZE, IMAGE_SIZE), dtype=float, device=device)
    speed = wp.zeros((IMAGE_SIZE, IMAGE_SIZE), dtype=float, device=device)
    scale = IMAGE_SIZE / (2 * 2.0 * 1.35 + 0.3)

    print(f"weft demo: {n} particles on {device}, {STEPS} steps of {DT:.5f} s")
    t0 = time.perf_counter()
    wp.load_module(device=device)       # compile ahead of time (cached by the daemon)
    compile_s = time.perf_counter() - t0
    print(f"  module compiled in {compile_s * 1000:.1f} ms")

    e_start, e_start_ref = total_energy(x, v)
    # free fall: no particle can reach the floor in FREE_FALL_STEPS steps
    for _ in range(FREE_FALL_STEPS):
        wp.launch(integrate, dim=n, inputs=[x, v, DT])
    k = FREE_FALL_STEPS
    g = np.array([0.0, -9.81, 0.0])
    exact = x0.astype(np.float64) + k * DT * v0.astype(np.float64) + DT * DT * g * k * (k + 1) / 2
    free_fall_error = float(np.max(np.abs(x.numpy() - exact)))
    e_free, e_free_ref = total_energy(x, v)

    frames = []
    step_times = []
    for step in range(FREE_FALL_STEPS, STEPS):
        t = time.perf_counter()
        wp.launch(integrate, dim=n, inputs=[x, v, DT])
        wp.launch(collide, dim=n, inputs=[x, v, DT])
        wp.synchronize()
        step_times.append(time.perf_counter() - t)
        if step % FRAME_EVERY == 0 or step == STEPS - 1:
            image.zero_()
            speed.zero_()
            wp.launch(splat, dim=n, inputs=[x, v, image, speed, IMAGE_SIZE, scale])
            path = out_dir / f"frame_{len(frames):03d}.png"
            write_png(path, tone_map(image.numpy(), speed.numpy(), scale))
            frames.append(path)
    e_end, e_end_ref = total_energy(x, v)
    positions = x.numpy()

    ms = np.array(step_times) * 1000
    print(f"  time per step (integrate + collide, synchronized): median {np.median(ms):.3f} ms, "
          f"min {ms.min():.3f} ms, {n / (np.median(ms) / 1000) / 1e6:.1f} M particles/s")
    print(f"  free fall after {k} steps: max |x - exact| = {free_fall_error:.3e} m "
          f"(float32 kernel vs float64 recurrence)")
    drift = abs(e_free_ref - e_start_ref) / abs(e_start_ref)
    print(f"  energy (all particles, unit mass): start {e_start_ref:.6e} J, after free fall "
          f"{e_free_ref:.6e} "
          f"(relative drift {drift:.2e}, O(dt) for semi-implicit Euler), end {e_end_ref:.6e}")
    reduction_error = max(abs(e_start - e_start_ref) / abs(e_start_ref),
                          abs(e_end - e_end_ref) / abs(e_end_ref))
    print(f"  energy by atomic_add in a kernel vs float64 NumPy: worst relative error "
          f"{reduction_error:.2e}")
    inside = np.all((positions[:, 1] >= -1e-3) & (np.abs(positions[:, 0]) <= 2.0 + 1e-3) &
                    (np.abs(positions[:, 2]) <= 2.0 + 1e-3))
    print(f"  all particles inside the box: {bool(inside)}")
    print(f"  wrote {len(frames)} PNG frames to {out_dir}/ (frame_000.png .. {frames[-1].name})")

    ok = free_fall_error < 1e-3 and drift < 0.05 and reduction_error < 1e-3 and inside and \
        e_end_ref < e_free_ref
    print("demo: OK" if ok else "demo: CHECK FAILED")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
