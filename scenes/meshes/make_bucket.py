#!/usr/bin/env python3
"""Writes bucket.obj: an excavator-style scoop as one closed, thick-walled mesh (the DEM
shell is sampled from its signed distance field, so it must be closed and outward-wound).

Body frame before centring: a bottom plate x in [0, L], z in [-W/2, W/2], y in [0, T]; a
back wall x in [0, T], y in [0, H]; two side walls |z| in [W/2 - T, W/2], y in [0, H]. Open
at the top (y = H) and at the front (x = L): dragged along +x through the soil, the cut soil
enters through the front. The solid is a union of cubes of side V on a grid; its boundary
is written as two triangles per exposed cube face (coplanar faces stay separate: the mesh is
closed and manifold because no two cubes meet along an edge only). The vertices are then
shifted so that the solid's centroid is the origin (scenes put bodies at their centroid).

Sizes (m): L = 0.64, W = 0.64, H = 0.40, T = 0.08 (walls two granules of r = 4 cm thick),
V = 0.04. Inner cavity 0.56 x 0.48 x 0.32 m = 0.086 m^3.

Usage: make_bucket.py > bucket.obj
"""
import sys

V = 0.04
NL, NW, NH, NT = 16, 16, 10, 2  # L, W, H, T in cubes


def solid(i, j, k):  # cube i along x, j along y, k along z
    if not (0 <= i < NL and 0 <= j < NH and 0 <= k < NW):
        return False
    return j < NT or i < NT or k < NT or k >= NW - NT


verts = {}
vlist = []
faces = []


def vid(p):
    if p not in verts:
        verts[p] = len(vlist) + 1
        vlist.append(p)
    return verts[p]


# For each cube and each of its 6 faces with empty space beyond: the face's 4 corners,
# counter-clockwise seen from outside (along the outward normal).
DIRS = [((1, 0, 0), [(1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1)]),
        ((-1, 0, 0), [(0, 0, 0), (0, 0, 1), (0, 1, 1), (0, 1, 0)]),
        ((0, 1, 0), [(0, 1, 0), (0, 1, 1), (1, 1, 1), (1, 1, 0)]),
        ((0, -1, 0), [(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)]),
        ((0, 0, 1), [(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]),
        ((0, 0, -1), [(0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 0)])]
for i in range(NL):
    for j in range(NH):
        for k in range(NW):
            if not solid(i, j, k):
                continue
            for (di, dj, dk), quad in DIRS:
                if solid(i + di, j + dj, k + dk):
                    continue
                ids = [vid((i + a, j + b, k + c)) for a, b, c in quad]
                faces.append((ids[0], ids[1], ids[2]))
                faces.append((ids[0], ids[2], ids[3]))

# Centroid of the solid: the mean of its cubes' centres (all cubes have the same volume).
cubes = [(i, j, k) for i in range(NL) for j in range(NH) for k in range(NW) if solid(i, j, k)]
cx = sum(c[0] + 0.5 for c in cubes) / len(cubes)
cy = sum(c[1] + 0.5 for c in cubes) / len(cubes)
cz = sum(c[2] + 0.5 for c in cubes) / len(cubes)
out = sys.stdout
out.write("# excavator bucket, open top and front, %d cubes of %g m, centroid at the origin "
          "(scenes/meshes/make_bucket.py)\n" % (len(cubes), V))
out.write("# before centring the centroid was at (%.6f, %.6f, %.6f) m; z offset -W/2\n" % (cx * V, cy * V, (cz - NW / 2) * V))
for (a, b, c) in vlist:
    out.write("v %.6f %.6f %.6f\n" % ((a - cx) * V, (b - cy) * V, (c - cz) * V))
for f in faces:
    out.write("f %d %d %d\n" % f)
