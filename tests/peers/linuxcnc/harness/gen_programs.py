#!/usr/bin/python3
"""Generate the CAM-like test programs (deterministic: fixed seeds, identical on every run).

Usage: gen_programs.py [OUTDIR]
OUTDIR defaults to $LCNC_OUT_DIR/programs/gen, LCNC_OUT_DIR to the harness's out/ directory."""
import math, os, random, sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = (sys.argv[1] if len(sys.argv) > 1 else
       str(Path(os.environ.get("LCNC_OUT_DIR") or HERE / "out") / "programs" / "gen"))
os.makedirs(OUT, exist_ok=True)

def f(v):
    s = f"{v:.4f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s

def write(name, comment, mode, body):
    with open(os.path.join(OUT, name + ".ngc"), "w") as fh:
        fh.write(f"({comment})\n")
        fh.write("G21 G90 G17" + (f" {mode}" if mode else "") + "\n")
        fh.write("\n".join(body) + "\nM2\n")

def resample(curve, total_param, n_seg, lmin, lmax, seed):
    """Points along curve(t), t in [0,total_param], with chord lengths drawn uniformly
    in [lmin,lmax] (by fine arc-length table)."""
    rng = random.Random(seed)
    N = 200000
    ts = [total_param * i / N for i in range(N + 1)]
    pts = [curve(t) for t in ts]
    s = [0.0]
    for a, b in zip(pts, pts[1:]):
        s.append(s[-1] + math.dist(a, b))
    out = [pts[0]]
    target, j = 0.0, 0
    for _ in range(n_seg):
        target += rng.uniform(lmin, lmax)
        while j < N and s[j + 1] < target:
            j += 1
        if j >= N:
            break
        u = (target - s[j]) / (s[j + 1] - s[j])
        out.append(tuple(pts[j][k] + u * (pts[j + 1][k] - pts[j][k]) for k in range(len(pts[j]))))
    return out

# (a) 2000 short G1 segments 0.1-0.5 mm on smooth curves, F3000
sine = lambda t: (t, 10 * math.sin(2 * math.pi * t / 40))
spiral = lambda t: ((5 + 1.5 * t) * math.cos(t), (5 + 1.5 * t) * math.sin(t))
for cname, curve, T in (("sine", sine, 2000.0), ("spiral", spiral, 60.0)):
    pts = resample(curve, T, 2000, 0.1, 0.5, seed=1)
    body = [f"G0 X{f(pts[0][0])} Y{f(pts[0][1])} Z0", "G1 F3000"]
    body += [f"X{f(x)} Y{f(y)}" for x, y in pts[1:]]
    for mode, tag in (("", "g64"), ("G64 P0.01", "g64p001")):
        write(f"a_polyline_{cname}_{tag}",
              f"{len(pts)-1} G1 segments 0.1-0.5 mm along a {cname}, F3000, {mode or 'no G64 word'}",
              mode, body)

# (b) raster zigzag pocket 40 x 30 mm, stepover 1 mm, 90 deg corners, F2000
body = ["G0 X0 Y0 Z2", "G1 Z-1 F500", "G1 F2000"]
y = 0
for i in range(31):
    x = 40 if i % 2 == 0 else 0
    body.append(f"X{x} Y{y}")
    if i < 30:
        y += 1
        body.append(f"X{x} Y{y}")
body.append("G0 Z5")
for mode, tag in (("G64", "g64"), ("G61", "g61"), ("G64 P0.01", "g64p001")):
    write(f"b_zigzag_pocket_{tag}", f"raster zigzag pocket 40x30 mm, stepover 1 mm, F2000, {mode}", mode, body)

# (c) chain of tangent G3/G2 semicircles (S-curves), radii 2-20 mm, F4000
rng = random.Random(3)
x = 0.0
body = ["G0 X0 Y0 Z0", "G1 F4000"]
for i in range(24):
    r = round(rng.uniform(2, 20), 3)
    g = "G3" if i % 2 == 0 else "G2"
    body.append(f"{g} X{f(x + 2 * r)} Y0 I{f(r)} J0")
    x += 2 * r
write("c_tangent_arcs_g64", "24 tangent G3/G2 semicircles, radii 2-20 mm, F4000, default G64", "", body)

# (d) 40 x 40 mm square with 5 mm corner radii, 5 laps, F3000
R, L = 5, 40
lap = [f"G1 X{L-R} Y0", f"G3 X{L} Y{R} I0 J{R}", f"G1 X{L} Y{L-R}", f"G3 X{L-R} Y{L} I{-R} J0",
       f"G1 X{R} Y{L}", f"G3 X0 Y{L-R} I0 J{-R}", f"G1 X0 Y{R}", f"G3 X{R} Y0 I{R} J0"]
body = ["G0 X5 Y0 Z0", "F3000"] + lap * 5
write("d_rounded_square_x5_g64", "40 mm square, 5 mm corner radii, 5 laps, F3000, default G64", "", body)
write("d_rounded_square_x5_g64p001", "40 mm square, 5 mm corner radii, 5 laps, F3000, G64 P0.01", "G64 P0.01", body)

# (e) short segments (0.5-2 mm) turning by `turn(rng, i, heading)` degrees, F6000
def walk_body(seed, turn):
    rng = random.Random(seed)
    x = y = ang = 0.0
    pts = [(0.0, 0.0)]
    for i in range(600):
        ang += turn(rng, i, ang)
        l = rng.uniform(0.5, 2.0)
        x += l * math.cos(math.radians(ang)); y += l * math.sin(math.radians(ang))
        pts.append((x, y))
    return ["G0 X0 Y0 Z0", "G1 F6000"] + [f"X{f(px)} Y{f(py)}" for px, py in pts[1:]]

def small_turn(rng, i, ang):
    # 3-10 deg, random sign, the heading kept within +-60 deg of +X so the path progresses
    d = rng.uniform(3, 10) * (1 if rng.random() < 0.5 else -1)
    return -d if abs(ang + d) > 60 else d

body = walk_body(5, small_turn)
write("e_small_turns_f6000_g64", "600 G1 segments 0.5-2 mm, turns 3-10 deg, F6000, default G64", "", body)
write("e_small_turns_f6000_g64p001", "600 G1 segments 0.5-2 mm, turns 3-10 deg, F6000, G64 P0.01", "G64 P0.01", body)
# same but smaller turns 1-4 deg (a finely tessellated curve at full feed)
body = walk_body(6, lambda rng, i, ang: rng.uniform(1, 4) * (1 if (i // 15) % 2 == 0 else -1))
write("e2_tiny_turns_f6000_g64", "600 G1 segments 0.5-2 mm, turns 1-4 deg in runs of 15, F6000, default G64", "", body)

# (f1) helical bore: radius 5, 10 turns, 1 mm pitch, F2000
body = ["G0 X5 Y0 Z1", "G1 Z0 F500", "F2000"]
for i in range(1, 11):
    body.append(f"G2 X5 Y0 Z{-i} I-5 J0")
body += ["G2 X5 Y0 I-5 J0", "G0 Z5"]
write("f1_helix_r5_10turns", "helical bore R5, 10 turns, pitch 1 mm, F2000, default G64", "", body)

# (f2) 3D surface finishing raster: 30 x 20 mm, passes along X with 0.5 mm segments, stepover 0.5 mm
surf = lambda x, y: 2.0 * math.sin(x / 6.0) * math.cos(y / 5.0) - 3.0
body = ["G0 X0 Y0 Z2", f"G1 Z{f(surf(0,0))} F1000", "F3000"]
ny, nx = 41, 61
for j in range(ny):
    yv = 0.5 * j
    xs = [0.5 * i for i in range(nx)]
    if j % 2:
        xs.reverse()
    if j > 0:
        body.append(f"X{f(xs[0])} Y{f(yv)} Z{f(surf(xs[0], yv))}")
    for xv in xs[1:]:
        body.append(f"X{f(xv)} Y{f(yv)} Z{f(surf(xv, yv))}")
body.append("G0 Z5")
for mode, tag in (("", "g64"), ("G64 P0.01", "g64p001")):
    write(f"f2_surface_raster_{tag}", f"3D finishing raster 30x20 mm, 0.5 mm steps, F3000, {mode or 'default G64'}", mode, body)

# (f3) drilling-like pattern: 5x5 holes, rapids between, G1 plunge 3 mm at F300
body = ["G0 Z5"]
for j in range(5):
    for i in range(5):
        xi = 10 * (i if j % 2 == 0 else 4 - i)
        body += [f"G0 X{xi} Y{10*j}", "G0 Z1", "G1 Z-3 F300", "G0 Z5"]
write("f3_hole_pattern_rapids", "5x5 holes: G0 moves, G1 Z-3 F300 plunges, G0 retracts, default G64", "", body)

# (f4) contour with tangent line-arc transitions (slot/obround), 3 laps, F4000
body = ["G0 X0 Y0 Z0", "F4000"]
for k in range(3):
    body += ["G1 X40 Y0", "G3 X40 Y10 I0 J5", "G1 X0 Y10", "G3 X0 Y0 I0 J-5"]
write("f4_obround_x3", "obround 40x10 mm, tangent line-arc transitions, 3 laps, F4000, default G64", "", body)

# ---- second batch (g*): probing the classes found slower in the first batch ----
def turns_prog(name, comment, feed, lo, hi, seed, n=600, lmin=0.5, lmax=2.0, mode=""):
    rng = random.Random(seed)
    x = y = ang = 0.0
    pts = []
    for i in range(n):
        d = rng.uniform(lo, hi) * (1 if rng.random() < 0.5 else -1)
        if abs(ang + d) > 60:
            d = -d
        ang += d
        l = rng.uniform(lmin, lmax)
        x += l * math.cos(math.radians(ang)); y += l * math.sin(math.radians(ang))
        pts.append((x, y))
    body = ["G0 X0 Y0 Z0", f"G1 F{feed}"] + [f"X{f(px)} Y{f(py)}" for px, py in pts]
    write(name, comment, mode, body)

turns_prog("g1_small_turns_f3000_g64", "600 G1 segments 0.5-2 mm, turns 3-10 deg, F3000, default G64", 3000, 3, 10, 5)
turns_prog("g2_small_turns_f1000_g64", "600 G1 segments 0.5-2 mm, turns 3-10 deg, F1000, default G64", 1000, 3, 10, 5)
turns_prog("g3_turns_15_30_f6000_g64", "300 G1 segments 1-3 mm, turns 15-30 deg, F6000, default G64", 6000, 15, 30, 7, n=300, lmin=1, lmax=3)
# fine polygon: circle R50 as 314 chords of ~1 mm (1.15 deg turns), F6000, no P, 2 laps
body = ["G0 X50 Y0 Z0", "G1 F6000"]
N = 314
for lapn in range(2):
    for i in range(1, N + 1):
        a = 2 * math.pi * i / N
        body.append(f"X{f(50*math.cos(a))} Y{f(50*math.sin(a))}")
write("g4_fine_polygon_r50_f6000_g64", "circle R50 as 314 chords of 1 mm, 1.15 deg turns, 2 laps, F6000, default G64", "", body)
# rapid-only chain with 90 deg corners (G0 zigzag), like positioning between features
body = ["G0 X0 Y0 Z5"]
for i in range(20):
    body.append(f"G0 X{40 if i % 2 == 0 else 0} Y{2*i}")
    body.append(f"G0 X{40 if i % 2 == 0 else 0} Y{2*i+2}")
write("g5_rapid_zigzag", "G0-only zigzag, 40 mm legs, 2 mm steps, 90 deg corners", "", body)
# 50 mm square, sharp 90 deg corners at F6000, 3 laps, default G64
body = ["G0 X0 Y0 Z0", "G1 F6000"] + ["X50 Y0", "X50 Y50", "X0 Y50", "X0 Y0"] * 3
write("g6_square_f6000_g64", "50 mm square, sharp corners, 3 laps, F6000, default G64", "", body)

# ---- third batch: the no-P programs again with an explicit P near LinuxCNC's own deviation ----
def with_mode(src, dst, mode, old_note, new_note):
    lines = open(os.path.join(OUT, src + ".ngc")).read().splitlines()
    lines[0] = lines[0].replace(old_note, new_note)
    lines[1] = "G21 G90 G17 " + mode
    open(os.path.join(OUT, dst + ".ngc"), "w").write("\n".join(lines) + "\n")

with_mode("g4_fine_polygon_r50_f6000_g64", "g4_fine_polygon_r50_f6000_g64p0003", "G64 P0.003", "default G64", "G64 P0.003")
with_mode("e_small_turns_f6000_g64", "e_small_turns_f6000_g64p004", "G64 P0.04", "default G64", "G64 P0.04")
with_mode("a_polyline_sine_g64", "a_polyline_sine_g64p0006", "G64 P0.006", "no G64 word", "G64 P0.006")
# ---- fourth batch: dense CAM arcs, their vertices rounded to the decimals a post writes ----
def dense_arc(name, comment, radius, chord, decimals, n, feed=3000, first=0):
    """Chords `first` .. `first + n - 1` of an arc about (50, 50), from angle 0 on."""
    body = [f"G0 X{f(50 + radius)} Y50 Z0", f"G1 F{feed}"]
    for i in range(first, first + n):
        a = i * chord / radius
        x, y = 50 + radius * math.cos(a), 50 + radius * math.sin(a)
        body.append(f"X{x:.{decimals}f} Y{y:.{decimals}f}")
    write(name, comment, "G64 P0.01", body)

dense_arc("h1_dense_arc_r10_20um_4dec", "R10 in 2000 chords of 20 um, rounded to 0.1 um, F3000, G64 P0.01",
          10, 0.02, 4, 2000)
dense_arc("h2_dense_arc_r10_20um_6dec", "the same, rounded to 1 nm", 10, 0.02, 6, 2000)
dense_arc("h3_dense_arc_r20_100um_3dec", "R20 in 4000 chords of 0.1 mm, rounded to 1 um, F3000, G64 P0.01",
          20, 0.1, 3, 4000)
# arcs of R5/R20/R50 in chords of 0.05 and 0.2 mm at 1 um, F1500 and F6000 (at most 3000 chords)
for R in (5, 20, 50):
    for chord in (0.05, 0.2):
        for F in (1500, 6000):
            n = int(min(3000, 2 * math.pi * R / chord))
            dense_arc(f"i_dense_r{R}_c{f(chord)}_f{F}", f"R{R} in {n} chords of {chord} mm at 1 um, F{F}, G64 P0.01",
                      R, chord, 3, n, feed=F, first=1)
print(f"{len(os.listdir(OUT))} programs in {OUT}")
