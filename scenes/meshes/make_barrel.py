#!/usr/bin/env python3
"""Writes barrel.obj: a closed cylinder (radius 0.3 m, height 0.9 m, axis y, centred on the
origin) with N side segments, faces counter-clockwise seen from outside.

The inscribed N-gon's area is (N/2) r^2 sin(2 pi/N); its relative deficit from pi r^2 is
1 - sin(x)/x with x = 2 pi/N, at most x^2/6 = 0.16 % for N = 64.

Usage: make_barrel.py [--open] > file.obj   (--open leaves out the top cap: N open edges)
"""
import math
import sys

N, R, H = 64, 0.3, 0.9
open_top = "--open" in sys.argv[1:]
out = sys.stdout
out.write("# closed cylinder r=%g m h=%g m, %d segments%s (scenes/meshes/make_barrel.py)\n"
          % (R, H, N, ", top cap missing" if open_top else ""))
for y in (-H / 2, H / 2):
    for i in range(N):
        a = 2 * math.pi * i / N
        out.write("v %.9f %.9f %.9f\n" % (R * math.cos(a), y, -R * math.sin(a)))
out.write("v 0 %.9f 0\nv 0 %.9f 0\n" % (-H / 2, H / 2))
bottom_c, top_c = 2 * N + 1, 2 * N + 2  # 1-based OBJ indices
for i in range(N):
    j = (i + 1) % N
    b0, b1, t0, t1 = i + 1, j + 1, N + i + 1, N + j + 1
    # vertices go counter-clockwise around +y (angle measured towards -z), so the side
    # quad b0 b1 t1 t0 faces outwards.
    out.write("f %d %d %d\nf %d %d %d\n" % (b0, b1, t1, b0, t1, t0))
    out.write("f %d %d %d\n" % (bottom_c, b1, b0))       # bottom cap faces -y
    if not open_top:
        out.write("f %d %d %d\n" % (top_c, t0, t1))      # top cap faces +y
