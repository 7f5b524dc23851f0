#!/usr/bin/python3
"""Machining time from halsampler -t output (sample-number X Y Z per 1 ms servo period).
Time = (last sample whose position differs from the previous one) - (first such sample) + 1
servo periods, i.e. the number of servo periods during which the commanded position moves
(from the first period that moves to the last). Also reports gaps in sample numbers."""
import json, sys

def analyze(path, period=0.001):
    rows = []
    with open(path) as f:
        for line in f:
            p = line.split()
            if len(p) >= 4:
                rows.append((int(p[0]), float(p[1]), float(p[2]), float(p[3])))
    if not rows:
        return {"samples": 0}
    gaps = sum(1 for a, b in zip(rows, rows[1:]) if b[0] != a[0] + 1)
    moving = [i for i in range(1, len(rows)) if rows[i][1:] != rows[i - 1][1:]]
    res = {"samples": len(rows), "gaps": gaps}
    if moving:
        k1, k2 = moving[0], moving[-1]
        res["time_s"] = round((rows[k2][0] - rows[k1][0] + 1) * period, 6)
        res["idle_before"] = k1 - 1
        res["idle_after"] = len(rows) - 1 - k2
        res["start"] = rows[k1 - 1][1:]
        res["end"] = rows[k2][1:]
        # path length of the sampled commanded positions
        L = 0.0
        for i in range(k1, k2 + 1):
            a, b = rows[i - 1], rows[i]
            L += ((b[1]-a[1])**2 + (b[2]-a[2])**2 + (b[3]-a[3])**2) ** 0.5
        res["path_mm"] = round(L, 4)
        vmax = max(((rows[i][1]-rows[i-1][1])**2 + (rows[i][2]-rows[i-1][2])**2 +
                    (rows[i][3]-rows[i-1][3])**2) ** 0.5 for i in moving) / period
        res["vmax_mm_s"] = round(vmax, 3)
    return res

if __name__ == "__main__":
    print(json.dumps(analyze(sys.argv[1])))
