#!/usr/bin/python3
"""Scene families for index benchmarks, written independently of `voxtrace gen`.

The index must be fast on scenes it was not tuned for; these are drawn by a
different program with different rules, so a benchmark on them is not a
benchmark on the generator the index was developed against.

    bench/families.py FAMILY --spheres N [--seed S] [--res W H] -o FILE

Families (every sphere inside the default camera's frustum unless said):
  uniform     radii within ±20% of one size, centres uniform in the frustum
              between depths 2 and 12 (near spheres cover many pixels)
  mixed       the same volume, radii log-uniform over three decades
  clustered   about N^(1/3) clumps of very unequal population (weights u³),
              clump radii log-uniform in 0.15..1, each clump's sphere size set
              by its own fill fraction (sizes differ up to 10× between
              clumps), 2% dust through the frustum, one floor sphere of
              radius 1000
  straddle    radii within ±20% of a size chosen to sit on a power-of-four
              boundary of the diameter (where fixed size bands split a narrow
              range in two)
  shell       spheres on the surface of one big hollow ball (a surface, not a
              volume: rays cross an empty interior)
  floor       small spheres resting on a radius-1000 floor sphere, spread far
              towards the horizon
  inside      clustered, with the camera inside the biggest clump
  islands     clustered's clumps alone in empty space: no dust, no floor
              (most primary rays meet nothing)
  hugetiny    one sphere of radius 1e6 far away and N tiny spheres (1e-3)
  fractal     clumps within clumps (Soneira-Peebles: 8 generations of 4
              sub-clumps, each 1.9 times smaller), one sphere size
  filaments   thin strands: about sqrt(N)/4 random walks of tiny spheres
              (radius 0.008) wandering far beyond the view, hair or fibres
  lognormal   uniform positions, radii log-normal (sigma 1.6: four decades
              hold 95% of them)
  onion       five concentric shells of spheres (rays cross several
              surfaces and the hollows between them)
  sheet       a flat carpet of small spheres out to the horizon, seen at a
              grazing angle

`--density K` scales how many spheres a primary ray crosses (default 4).
"""
import argparse
import math
import sys

import numpy as np

Z_NEAR, Z_FAR, WIDTH = 2.0, 12.0, 0.95


def frustum_points(rng, n, z0=Z_NEAR, z1=Z_FAR):
    """Uniform in the frustum's volume between depths z0 and z1."""
    u = rng.random(n)
    z = (z0 ** 3 + (z1 ** 3 - z0 ** 3) * u) ** (1 / 3)
    half = WIDTH * z
    x = (rng.random(n) * 2 - 1) * half
    y = (rng.random(n) * 2 - 1) * half
    return np.stack([x, y, -z], axis=1)


def frustum_volume(z0=Z_NEAR, z1=Z_FAR):
    return (2 * WIDTH) ** 2 * (z1 ** 3 - z0 ** 3) / 3


def crossing_radius(n, density):
    """Radius at which n balls in the frustum are crossed `density` times per ray."""
    return math.sqrt(density * frustum_volume() / (n * math.pi * (Z_FAR - Z_NEAR)))


def ball_points(rng, n):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v * rng.random((n, 1)) ** (1 / 3)


def uniform(rng, n, density):
    r = crossing_radius(n, density) * rng.uniform(0.8, 1.2, n)
    return frustum_points(rng, n), r


def mixed(rng, n, density):
    k = 1000.0
    base = crossing_radius(n, density) / math.sqrt((k * k - 1) / (2 * math.log(k)))
    return frustum_points(rng, n), base * k ** rng.random(n)


def straddle(rng, n, density):
    # Diameter 2r near 4^j: pick j closest to the covering size.
    r0 = crossing_radius(n, density)
    j = round(math.log(2 * r0, 4))
    r = 0.5 * 4.0 ** j * rng.uniform(0.8, 1.2, n)
    return frustum_points(rng, n), r


def clumps(rng, n, fill_lo=0.05, fill_hi=0.3):
    count = max(1, round(n ** (1 / 3)))
    weights = rng.random(count) ** 3
    weights /= weights.sum()
    population = rng.multinomial(n, weights)
    radii = 0.15 * (1 / 0.15) ** rng.random(count)
    centres = frustum_points(rng, count, Z_NEAR + 1.0, Z_FAR - 1.0)
    fills = fill_lo * (fill_hi / fill_lo) ** rng.random(count)
    pts, rs = [], []
    for c, R, m, f in zip(centres, radii, population, fills):
        if m == 0:
            continue
        # m balls of radius s fill f of the clump: m s³ = f R³.
        s = R * (f / m) ** (1 / 3)
        pts.append(c + ball_points(rng, m) * R)
        rs.append(s * rng.uniform(0.8, 1.2, m))
    return np.concatenate(pts), np.concatenate(rs), centres, radii, population


def clustered(rng, n, density, camera_inside=False):
    dust = n // 50
    p, r, centres, radii, population = clumps(rng, n - dust - 1)
    dust_r = crossing_radius(max(dust, 1), 0.5) * rng.uniform(0.8, 1.2, dust)
    p = np.concatenate([p, frustum_points(rng, dust), [[0.0, -1002.0, -7.0]]])
    r = np.concatenate([r, dust_r, [1000.0]])
    if camera_inside:
        big = int(np.argmax(population * radii ** 0))
        # Move everything so the camera (origin) sits in the biggest clump's middle.
        p -= centres[big]
    return p, r


def shell(rng, n, density):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    R = 4.0
    centre = np.array([0.0, 0.0, -8.0])
    # n balls cover the shell's area about twice: n π s² = 2 · 4π R².
    s = math.sqrt(8 * R * R / n)
    return centre + v * R, s * rng.uniform(0.8, 1.2, n)


def floor(rng, n, density):
    R = 1000.0
    centre = np.array([0.0, -1001.0, 0.0])
    # Points on the floor's cap under the frustum, out towards the horizon.
    x = rng.uniform(-60, 60, n - 1)
    z = -rng.uniform(2, 120, n - 1) ** 1.0
    s = 0.02 * 10 ** rng.random(n - 1)
    y = centre[1] + np.sqrt(R * R - x * x - z * z) + s
    p = np.stack([x, y, z], axis=1)
    return np.concatenate([p, [centre]]), np.concatenate([s, [R]])


def hugetiny(rng, n, density):
    p = frustum_points(rng, n - 1)
    r = np.full(n - 1, 1e-3) * rng.uniform(0.8, 1.2, n - 1)
    return np.concatenate([p, [[0.0, 0.0, -2.0e6]]]), np.concatenate([r, [1.0e6]])


def fractal(rng, n, density):
    eta, shrink, generations = 4, 1.9, 8
    pts, R = np.array([[0.0, 0.0, -7.0]]), 4.0
    for _ in range(generations):
        pts = np.repeat(pts, eta, axis=0) + ball_points(rng, len(pts) * eta) * R
        R /= shrink
    p = pts[rng.choice(len(pts), n, replace=len(pts) < n)] + ball_points(rng, n) * R
    return p, 0.5 * crossing_radius(n, density) * rng.uniform(0.8, 1.2, n)


def filaments(rng, n, density):
    strands = max(1, int(math.sqrt(n) / 4))
    per = n // strands
    ps = []
    for _ in range(strands):
        start = frustum_points(rng, 1)[0]
        drift = rng.normal(size=3)
        drift /= np.linalg.norm(drift)
        steps = rng.normal(size=(per, 3)) * 0.02 + drift * 0.01
        ps.append(start + np.cumsum(steps, axis=0))
    p = np.concatenate(ps)
    return p, np.full(len(p), 0.008) * rng.uniform(0.8, 1.2, len(p))


def lognormal(rng, n, density):
    r = np.exp(rng.normal(0.0, 1.6, n))
    r *= crossing_radius(n, density) / math.sqrt(np.mean(r ** 2))
    return frustum_points(rng, n), r


def onion(rng, n, density):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    radius = 1.0 + 0.8 * rng.integers(0, 5, n)
    s = 0.5 * math.sqrt(8 * 16 / n)
    return np.array([0.0, 0.0, -8.0]) + v * radius[:, None], s * rng.uniform(0.8, 1.2, n)


def sheet(rng, n, density):
    x = rng.uniform(-40, 40, n)
    z = -rng.uniform(1.5, 80, n)
    s = 0.03 * rng.uniform(0.8, 1.2, n)
    return np.stack([x, s - 1.5, z], axis=1), s


FAMILIES = {
    "uniform": uniform,
    "mixed": mixed,
    "clustered": clustered,
    "straddle": straddle,
    "shell": shell,
    "floor": floor,
    "inside": lambda rng, n, d: clustered(rng, n, d, camera_inside=True),
    "islands": lambda rng, n, d: clumps(rng, n)[:2],
    "hugetiny": hugetiny,
    "fractal": fractal,
    "filaments": filaments,
    "lognormal": lognormal,
    "onion": onion,
    "sheet": sheet,
}


def write(out, p, r, rng, res):
    w, h = res
    out.write("NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\n")
    out.write(f"RES {w} {h}\nBACK 0.1 0.1 0.15\nAMBIENT 0.3 0.3 0.3\n")
    out.write("LIGHT la -20 30 5 0.7 0.7 0.7\n")
    out.write("LIGHT lb 25 15 -4 0.4 0.4 0.4\n")
    out.write("LIGHT lc 0 40 -30 0.3 0.3 0.3\n")
    n = len(r)
    col = rng.random((n, 3))
    refl = np.where(rng.random(n) < 0.3, 0.3, 0.0)
    for i in range(n):
        x, y, z = p[i]
        s = r[i]
        c = col[i]
        out.write(f"SPHERE s{i} {x:.7g} {y:.7g} {z:.7g} {s:.5g} {s:.5g} {s:.5g} "
                  f"{c[0]:.2f} {c[1]:.2f} {c[2]:.2f} 0.2 0.6 0.4 {refl[i]:g} 40\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("family", choices=sorted(FAMILIES))
    ap.add_argument("--spheres", type=int, required=True)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--density", type=float, default=4.0)
    ap.add_argument("--res", type=int, nargs=2, default=[1024, 1024])
    ap.add_argument("-o", "--output", required=True)
    a = ap.parse_args()
    rng = np.random.default_rng(a.seed)
    p, r = FAMILIES[a.family](rng, a.spheres, a.density)
    with (sys.stdout if a.output == "-" else open(a.output, "w", buffering=1 << 20)) as out:
        write(out, p, r, rng, a.res)


if __name__ == "__main__":
    main()
