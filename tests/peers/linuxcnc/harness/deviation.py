#!/usr/bin/python3
"""Largest distance (mm) of LinuxCNC's sampled commanded positions from the programmed
polyline, for programs made of G0/G1 straight moves only (G90, mm). Usage:
deviation.py PROGRAM.ngc RUN.samples  -> prints JSON {max_dev_mm, at}"""
import json, re, sys
import numpy as np

def polyline(path):
    pos = [0.0, 0.0, 0.0]; pts = [tuple(pos)]
    for line in open(path):
        line = re.sub(r"\(.*?\)|;.*", "", line).upper()
        if re.search(r"G0?[23]\b|G5", line):
            return None
        words = dict((a, float(b)) for a, b in re.findall(r"([XYZ])\s*(-?[0-9.]+)", line))
        if not words:
            continue
        for i, a in enumerate("XYZ"):
            if a in words:
                pos[i] = words[a]
        if tuple(pos) != pts[-1]:
            pts.append(tuple(pos))
    return np.array(pts)

def max_dev(pts, samples):
    A, B = pts[:-1], pts[1:]
    D = B - A
    L2 = np.maximum((D * D).sum(1), 1e-30)
    worst, at = 0.0, None
    for chunk in np.array_split(samples, max(1, len(samples) // 500)):
        P = chunk[:, None, :]
        t = np.clip(((P - A) * D).sum(2) / L2, 0, 1)
        d = np.sqrt((((A + t[..., None] * D) - P) ** 2).sum(2)).min(1)
        i = int(d.argmax())
        if d[i] > worst:
            worst, at = float(d[i]), chunk[i].tolist()
    return worst, at

if __name__ == "__main__":
    pts = polyline(sys.argv[1])
    if pts is None:
        print(json.dumps({"max_dev_mm": None, "why": "arcs/NURBS in program"})); sys.exit()
    s = np.loadtxt(sys.argv[2])[:, 1:4]
    w, at = max_dev(pts, s)
    print(json.dumps({"max_dev_mm": round(w, 5), "at": at}))
