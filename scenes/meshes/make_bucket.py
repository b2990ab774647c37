#!/usr/bin/env python3
"""Writes bucket.obj: an excavator bucket as one closed, thick-walled mesh (the DEM shell is
sampled from its signed distance field, so it must be closed and outward-wound).

Body frame before centring: a box x in [0, L], y in [0, H], |z| <= W/2 with walls T thick
(bottom, top, back at x = 0 and the two sides), open at the front (x = L): the mouth.
Dragged along +x through the soil, the cut soil enters through the mouth; curled a quarter
turn (about +z) the mouth faces up and the bucket holds what it cut; turned mouth down it
pours it out. (A scoop open at the top as well holds only the wedge below its two lips, half
as much: tried first.) The solid is a union of cubes of side V on a grid; its boundary
is written as two triangles per exposed cube face (coplanar faces stay separate: the mesh is
closed and manifold because no two cubes meet along an edge only). The vertices are then
shifted so that the solid's centroid is the origin (scenes put bodies at their centroid).

Sizes (m): L = 0.64, W = 0.64, H = 0.48, T = 0.08 (walls two granules of r = 4 cm thick),
V = 0.04. Inner cavity 0.56 x 0.48 x 0.32 m = 0.086 m^3; mouth 0.48 x 0.32 m.

Usage: make_bucket.py > bucket.obj
"""
import sys

V = 0.04
NL, NW, NH, NT = 16, 16, 12, 2  # L, W, H, T in cubes


def solid(i, j, k):  # cube i along x, j along y, k along z
    if not (0 <= i < NL and 0 <= j < NH and 0 <= k < NW):
        return False
    return j < NT or j >= NH - NT or i < NT or k < NT or k >= NW - NT


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
out.write("# excavator bucket, open at the front (+x), %d cubes of %g m, centroid at the origin "
          "(scenes/meshes/make_bucket.py)\n" % (len(cubes), V))
out.write("# before centring the centroid was at (%.6f, %.6f, %.6f) m; z offset -W/2\n" % (cx * V, cy * V, (cz - NW / 2) * V))
for (a, b, c) in vlist:
    out.write("v %.6f %.6f %.6f\n" % ((a - cx) * V, (b - cy) * V, (c - cz) * V))
for f in faces:
    out.write("f %d %d %d\n" % f)
