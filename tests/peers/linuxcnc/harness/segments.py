#!/usr/bin/python3
"""List the stretches of motion between full stops in a .samples file (debug aid)."""
import sys, math
rows = [list(map(float, l.split())) for l in open(sys.argv[1])]
v = [0.0] + [math.dist(rows[i][1:], rows[i-1][1:]) * 1000 for i in range(1, len(rows))]
i, n = 1, len(rows)
while i < n:
    if v[i] > 0:
        j = i
        while j < n and v[j] > 0:
            j += 1
        L = sum(v[i:j]) / 1000
        print(f"move {i:6d}-{j-1:6d} {((j-i)/1000):7.3f}s  {L:8.3f}mm  vmax {max(v[i:j]):7.2f}  from {rows[i-1][1:]} to {rows[j-1][1:]}")
        i = j
    else:
        j = i
        while j < n and v[j] == 0:
            j += 1
        if i > 1 and j < n:
            print(f"  stop {j-i} ms")
        i = j
