//! `cnc cam`'s programs, run: every set-point of the cut, as the interpolator's engine
//! makes it from the program's blocks, lies on the geometry asked for, in both dialects.
//!
//! * `cnc cam ellipse`: on the ellipse (closed form, 1e-9 mm) or within the tolerance of
//!   its true offset (a search of this test's own: the closed-form offset point nearest
//!   each set-point, found by a dense scan and golden-section refinement).
//! * `cnc cam curves`: on the CAD file's curves, 1e-9 mm, measured against this test's
//!   own evaluator (Cox–de Boor's recursion on the curves as the file defines them,
//!   untrimmed; the nearest point by a scan and golden-section refinement; lines,
//!   circles and the ellipse in closed form), and reaching each curve's both ends.

use interpolator::engine::{BlockSource, Engine, Limits, TickState};
use interpreter::cam::curves::{curves_program, CurvesJob};
use interpreter::cam::{ellipse_program, EllipseJob, Job};
use shared::protocol::CommandBlock;
use shared::Machine;
use std::f64::consts::TAU;

const PERIOD_NS: u64 = 1_000_000;

struct Slice(Vec<CommandBlock>, usize);

impl BlockSource for Slice {
    fn next_block(&mut self) -> Option<CommandBlock> {
        let b = self.0.get(self.1).copied();
        self.1 += usize::from(b.is_some());
        b
    }
}

/// The set-points of `text` run on the built-in machine (mm).
fn set_points(text: &str) -> Vec<[f64; 3]> {
    let machine = Machine::default();
    let (_, blocks) = interpreter::process::compile(text, &machine, PERIOD_NS)
        .unwrap_or_else(|e| panic!("{e:?}\n{text}"));
    let mut engine = Engine::new(Limits::new(&machine, PERIOD_NS), [0.0; 3]);
    let mut src = Slice(blocks, 0);
    let mut out = Vec::new();
    for _ in 0..2_000_000 {
        let t = engine.tick(&mut src).unwrap();
        out.push(t.pos_mm);
        if t.state == TickState::Done {
            return out;
        }
    }
    panic!("never done")
}

fn job(a: f64, b: f64, offset: f64, fanuc: bool) -> EllipseJob {
    EllipseJob {
        a,
        b,
        centre: [12.0, -7.0],
        offset,
        tolerance: 1e-4,
        feed: 3000.0,
        depth: -1.0,
        fanuc,
    }
}

/// The ellipse is exact: every set-point of the cut on `((x−cx)/a)² + ((y−cy)/b)² = 1`,
/// to 1e-9 mm (the form's departure times the smaller semi-axis over two).
#[test]
fn the_ellipse_s_set_points_lie_on_it() {
    for fanuc in [false, true] {
        let j = job(90.0, 60.0, 0.0, fanuc);
        let (text, _) = ellipse_program(&j).unwrap();
        let cut: Vec<_> = set_points(&text)
            .into_iter()
            .filter(|p| p[2] == j.depth)
            .collect();
        assert!(cut.len() > 1000, "{}", cut.len());
        for p in &cut {
            let f = ((p[0] - j.centre[0]) / j.a).powi(2) + ((p[1] - j.centre[1]) / j.b).powi(2);
            let off = (f - 1.0).abs() * j.b / 2.0;
            assert!(
                off < 1e-9,
                "{p:?}: {off} mm off the ellipse (fanuc {fanuc})"
            );
        }
    }
}

/// The distance from `p` (relative to the centre) to the true offset at `d` of the
/// ellipse: the closed-form offset point `E(t) + d·n(t)` scanned at 20 000 angles, the
/// nearest refined by golden-section search over its neighbours.
fn to_offset(a: f64, b: f64, d: f64, p: [f64; 2]) -> f64 {
    let at = |t: f64| {
        let (e, de) = ([a * t.cos(), b * t.sin()], [-a * t.sin(), b * t.cos()]);
        let l = de[0].hypot(de[1]);
        let q = [e[0] + d * de[1] / l, e[1] - d * de[0] / l];
        (q[0] - p[0]).hypot(q[1] - p[1])
    };
    let n = 20_000;
    let k = (0..n)
        .min_by(|&i, &j| at(TAU * i as f64 / n as f64).total_cmp(&at(TAU * j as f64 / n as f64)))
        .unwrap();
    let (mut lo, mut hi) = (
        TAU * (k as f64 - 1.0) / n as f64,
        TAU * (k as f64 + 1.0) / n as f64,
    );
    let g = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..80 {
        let (x1, x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
        if at(x1) < at(x2) {
            hi = x2;
        } else {
            lo = x1;
        }
    }
    at((lo + hi) / 2.0)
}

/// Seed 004's case, a = 5, b = 3, offset 1 outward and inward: every set-point of the
/// cut within the 0.1 µm tolerance of the true offset (plus a nanometre for the
/// interpolation's own rounding).
#[test]
fn the_offset_s_set_points_keep_within_the_tolerance() {
    for (d, fanuc) in [(1.0, false), (1.0, true), (-1.0, false)] {
        let j = job(5.0, 3.0, d, fanuc);
        let (text, summary) = ellipse_program(&j).unwrap();
        assert!(summary.contains("control points"), "{summary}");
        let cut: Vec<_> = set_points(&text)
            .into_iter()
            .filter(|p| p[2] == j.depth)
            .collect();
        assert!(cut.len() > 500, "{}", cut.len());
        let mut worst = 0.0f64;
        for p in cut.iter().step_by(3) {
            worst = worst.max(to_offset(
                j.a,
                j.b,
                d,
                [p[0] - j.centre[0], p[1] - j.centre[1]],
            ));
        }
        assert!(
            worst <= j.tolerance + 1e-6,
            "offset {d}: {worst} mm (fanuc {fanuc})"
        );
        println!("offset {d}, fanuc {fanuc}: worst set-point {worst:.3e} mm from the true offset");
    }
}

/// Cox–de Boor's recursion: the basis function `i` of degree `p` at `u`, the last
/// non-empty span closed at its end.
fn cox_de_boor(i: usize, p: usize, k: &[f64], u: f64) -> f64 {
    if p == 0 {
        let last = k[k.len() - 1];
        let inside = k[i] <= u && u < k[i + 1];
        let end = u == last && k[i] < k[i + 1] && k[i + 1] == last;
        return if inside || end { 1.0 } else { 0.0 };
    }
    let mut v = 0.0;
    if k[i + p] > k[i] {
        v += (u - k[i]) / (k[i + p] - k[i]) * cox_de_boor(i, p - 1, k, u);
    }
    if k[i + p + 1] > k[i + 1] {
        v += (k[i + p + 1] - u) / (k[i + p + 1] - k[i + 1]) * cox_de_boor(i + 1, p - 1, k, u);
    }
    v
}

/// A curve as the test knows it, and the parameter range that is cut.
#[derive(Clone)]
enum Truth {
    Segment([f64; 2], [f64; 2]),
    /// `c + cos t·x + sin t·y`, `t` from `t0` to `t1` (radians).
    Conic {
        c: [f64; 2],
        x: [f64; 2],
        y: [f64; 2],
        t0: f64,
        t1: f64,
    },
    Spline {
        degree: usize,
        knots: Vec<f64>,
        pts: Vec<[f64; 2]>,
        w: Vec<f64>,
        u0: f64,
        u1: f64,
    },
}

impl Truth {
    fn range(&self) -> (f64, f64) {
        match self {
            Truth::Segment(..) => (0.0, 1.0),
            Truth::Conic { t0, t1, .. } => (*t0, *t1),
            Truth::Spline { u0, u1, .. } => (*u0, *u1),
        }
    }

    fn at(&self, u: f64) -> [f64; 2] {
        match self {
            Truth::Segment(a, b) => [a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1])],
            Truth::Conic { c, x, y, .. } => {
                let (s, co) = u.sin_cos();
                [c[0] + co * x[0] + s * y[0], c[1] + co * x[1] + s * y[1]]
            }
            Truth::Spline {
                degree,
                knots,
                pts,
                w,
                ..
            } => {
                let (mut num, mut den) = ([0.0; 2], 0.0);
                for (i, (p, w)) in pts.iter().zip(w).enumerate() {
                    let b = cox_de_boor(i, *degree, knots, u) * w;
                    num[0] += b * p[0];
                    num[1] += b * p[1];
                    den += b;
                }
                [num[0] / den, num[1] / den]
            }
        }
    }

    /// The cut range's knot spans (where the curve is smooth), 200 points each, for the
    /// nearest-point scan.
    fn samples(&self) -> Vec<Vec<(f64, [f64; 2])>> {
        let (a, b) = self.range();
        let mut cuts = vec![a];
        if let Truth::Spline { knots, .. } = self {
            cuts.extend(knots.iter().copied().filter(|&k| k > a && k < b));
        }
        cuts.push(b);
        cuts.dedup();
        cuts.windows(2)
            .map(|w| {
                (0..=200)
                    .map(|k| {
                        let u = w[0] + (w[1] - w[0]) * k as f64 / 200.0;
                        (u, self.at(u))
                    })
                    .collect()
            })
            .collect()
    }

    /// The distance from `q` to the cut range: in each knot span, every sample nearer
    /// than its neighbours (each basin of the distance) refined by golden-section search
    /// between them.
    fn distance(&self, spans: &[Vec<(f64, [f64; 2])>], q: [f64; 2]) -> f64 {
        let d = |p: [f64; 2]| (p[0] - q[0]).hypot(p[1] - q[1]);
        let g = (5f64.sqrt() - 1.0) / 2.0;
        let mut best = f64::INFINITY;
        for samples in spans {
            let ds: Vec<f64> = samples.iter().map(|s| d(s.1)).collect();
            let last = ds.len() - 1;
            let minima = (0..=last)
                .filter(|&i| (i == 0 || ds[i] <= ds[i - 1]) && (i == last || ds[i] <= ds[i + 1]));
            for i in minima {
                let (mut lo, mut hi) =
                    (samples[i.saturating_sub(1)].0, samples[(i + 1).min(last)].0);
                for _ in 0..90 {
                    let (x1, x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
                    if d(self.at(x1)) < d(self.at(x2)) {
                        hi = x2;
                    } else {
                        lo = x1;
                    }
                }
                best = best.min(d(self.at((lo + hi) / 2.0))).min(ds[i]);
            }
        }
        best
    }
}

/// Every set-point of the cut (at `depth`) within 1e-9 mm of one of `truths`, and each
/// truth's both ends within `reach` of a set-point. Returns the worst distance.
fn on_the_curves(points: &[[f64; 3]], depth: f64, truths: &[Truth], reach: f64) -> f64 {
    let cut: Vec<[f64; 2]> = points
        .iter()
        .filter(|p| (p[2] - depth).abs() < 1e-9)
        .map(|p| [p[0], p[1]])
        .collect();
    assert!(cut.len() > 100, "{} set-points at depth", cut.len());
    let samples: Vec<_> = truths.iter().map(Truth::samples).collect();
    let mut worst = 0.0f64;
    for q in &cut {
        let d = truths
            .iter()
            .zip(&samples)
            .map(|(t, s)| t.distance(s, *q))
            .fold(f64::INFINITY, f64::min);
        assert!(d < 1e-9, "set-point {q:?} is {d} mm from every curve");
        worst = worst.max(d);
    }
    for (i, t) in truths.iter().enumerate() {
        let (a, b) = t.range();
        for e in [t.at(a), t.at(b)] {
            let near = cut
                .iter()
                .map(|q| (q[0] - e[0]).hypot(q[1] - e[1]))
                .fold(f64::INFINITY, f64::min);
            assert!(
                near <= reach,
                "curve {i}: its end {e:?} is {near} mm from the cut"
            );
        }
    }
    worst
}

fn curves_job(fanuc: bool) -> CurvesJob {
    CurvesJob {
        cut: Job {
            feed: 3000.0,
            depth: -1.0,
            fanuc,
        },
        project: false,
    }
}

/// The example CAD file's curves as examples/make_cad_profile.py draws them.
fn example_truths() -> Vec<Truth> {
    let deg = std::f64::consts::PI / 180.0;
    let b4 = vec![
        [10.0, 57.0],
        [30.0, 82.0],
        [50.0, 62.0],
        [72.0, 86.0],
        [96.0, 71.0],
    ];
    let k4 = vec![0.0, 0.0, 0.0, 0.0, 0.4, 1.0, 1.0, 1.0, 1.0];
    let w4 = vec![1.0, 1.5, 0.8, 1.2, 1.0];
    let spline4 = Truth::Spline {
        degree: 3,
        knots: k4,
        pts: b4,
        w: w4,
        u0: 0.1,
        u1: 0.9,
    };
    let (a4, b4) = (spline4.at(0.9), spline4.at(0.1));
    vec![
        Truth::Segment([0.0, 0.0], [80.0, 0.0]),
        Truth::Conic {
            c: [80.0, 20.0],
            x: [20.0, 0.0],
            y: [0.0, 20.0],
            t0: -90.0 * deg,
            t1: 0.0,
        },
        Truth::Spline {
            degree: 3,
            knots: vec![0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 3.0, 3.0, 3.0],
            pts: vec![
                [100.0, 20.0],
                [104.0, 40.0],
                [96.0, 52.0],
                [104.0, 64.0],
                [a4[0] + 8.0, a4[1] + 4.0],
                a4,
            ],
            w: vec![1.0; 6],
            u0: 0.0,
            u1: 3.0,
        },
        spline4,
        Truth::Segment(b4, [20.0, 60.0]),
        Truth::Conic {
            c: [20.0, 20.0],
            x: [0.0, 40.0],
            y: [-20.0, 0.0],
            t0: 0.0,
            t1: 90.0 * deg,
        },
        Truth::Segment([0.0, 20.0], [0.0, 0.0]),
        Truth::Conic {
            c: [50.0, 35.0],
            x: [8.0, 0.0],
            y: [0.0, 8.0],
            t0: 0.0,
            t1: 360.0 * deg,
        },
    ]
}

/// The example CAD profile (a composite outline of a line, a circular arc, a uniform and
/// a trimmed rational B-spline run backwards, a line trimmed by points, an elliptic arc
/// and a polyline; and a whole circle): its program checks clean in both dialects and
/// every set-point lies on the curves to 1e-9 mm.
#[test]
fn the_example_cad_profile_is_cut_on_its_curves() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/cad-profile.step");
    let text = std::fs::read_to_string(path).unwrap();
    for fanuc in [false, true] {
        let job = curves_job(fanuc);
        let (program, summary) = curves_program(&text, "cad-profile.step", &job).unwrap();
        assert!(summary.starts_with("8 curves"), "{summary}");
        let worst = on_the_curves(&set_points(&program), -1.0, &example_truths(), 0.06);
        println!("fanuc {fanuc}: worst set-point {worst:.3e} mm from the CAD curves");
    }
}

/// A tiny Part 21 writer for the random curves.
struct Part21(Vec<String>);

impl Part21 {
    fn add(&mut self, s: String) -> usize {
        self.0.push(format!("#{}={s};", self.0.len() + 1));
        self.0.len()
    }
    fn point(&mut self, p: [f64; 2], z: f64) -> usize {
        self.add(format!("CARTESIAN_POINT('',({:?},{:?},{z:?}))", p[0], p[1]))
    }
    fn text(&self) -> String {
        format!(
            "ISO-10303-21;\nHEADER;\nFILE_SCHEMA(('CONFIG_CONTROL_DESIGN'));\nENDSEC;\nDATA;\n{}\nENDSEC;\nEND-ISO-10303-21;\n",
            self.0.join("\n")
        )
    }
}

/// xorshift64*: the test's own random numbers, seeded.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() * n as f64) as usize % n
    }
}

/// Random B-splines (degree 1 to 5, clamped or not, rational or not, with repeated
/// inner knots), trimmed at random parameters either way round, each alone in a file:
/// every set-point within 1e-9 mm of the untrimmed curve's trimmed range, both its ends
/// reached.
#[test]
fn random_trimmed_b_splines_are_cut_on_their_curves() {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    for case in 0..24 {
        let degree = 1 + rng.below(5);
        let n = degree + 1 + rng.below(8);
        let clamped = rng.below(2) == 0;
        let rational = rng.below(2) == 0;
        // Distinct knot values with multiplicities (inner ones at most the degree).
        let mut knots = Vec::new();
        let mut u = 0.0;
        while knots.len() < n + degree + 1 {
            let first = knots.is_empty();
            let left = n + degree + 1 - knots.len();
            let m = if clamped && (first || left == degree + 1) {
                degree + 1
            } else {
                (1 + rng.below(degree)).min(left)
            };
            knots.extend(std::iter::repeat_n(u, m));
            u += 0.2 + rng.next();
        }
        if clamped && knots.len() > n + degree + 1 {
            // The run before the end ate into it: restart this case's knots plainly.
            knots.truncate(n + degree + 1);
        }
        let pts: Vec<[f64; 2]> = (0..n)
            .map(|_| [rng.next() * 100.0 - 50.0, rng.next() * 100.0 - 50.0])
            .collect();
        let w: Vec<f64> = (0..n)
            .map(|_| {
                if rational {
                    0.3 + 2.0 * rng.next()
                } else {
                    1.0
                }
            })
            .collect();
        let (lo, hi) = (knots[degree], knots[n]);
        let mut t = [lo + (hi - lo) * rng.next(), lo + (hi - lo) * rng.next()];
        if (t[0] - t[1]).abs() < 0.05 * (hi - lo) {
            t = [lo, hi];
        }
        let forward = t[0] < t[1];
        let mut f = Part21(Vec::new());
        let ids: Vec<String> = pts
            .iter()
            .map(|p| format!("#{}", f.point(*p, 2.5)))
            .collect();
        let mut mult: Vec<(f64, usize)> = Vec::new();
        for &k in &knots {
            match mult.last_mut() {
                Some((v, m)) if *v == k => *m += 1,
                _ => mult.push((k, 1)),
            }
        }
        let ms: Vec<String> = mult.iter().map(|m| m.1.to_string()).collect();
        let ks: Vec<String> = mult.iter().map(|m| format!("{:?}", m.0)).collect();
        let curve = if rational {
            let ws: Vec<String> = w.iter().map(|x| format!("{x:?}")).collect();
            f.add(format!(
                "(BOUNDED_CURVE() B_SPLINE_CURVE({degree},({}),.UNSPECIFIED.,.F.,.F.) B_SPLINE_CURVE_WITH_KNOTS(({}),({}),.UNSPECIFIED.) CURVE() GEOMETRIC_REPRESENTATION_ITEM() RATIONAL_B_SPLINE_CURVE(({})) REPRESENTATION_ITEM(''))",
                ids.join(","), ms.join(","), ks.join(","), ws.join(",")
            ))
        } else {
            f.add(format!(
                "B_SPLINE_CURVE_WITH_KNOTS('',{degree},({}),.UNSPECIFIED.,.F.,.F.,({}),({}),.UNSPECIFIED.)",
                ids.join(","), ms.join(","), ks.join(",")
            ))
        };
        f.add(format!(
            "TRIMMED_CURVE('',#{curve},(PARAMETER_VALUE({:?})),(PARAMETER_VALUE({:?})),.{}.,.PARAMETER.)",
            t[0],
            t[1],
            if forward { "T" } else { "F" }
        ));
        let truth = Truth::Spline {
            degree,
            knots: knots.clone(),
            pts,
            w,
            u0: t[0].min(t[1]),
            u1: t[0].max(t[1]),
        };
        for fanuc in [false, true] {
            let job = curves_job(fanuc);
            let (program, _) = curves_program(&f.text(), "random.stp", &job)
                .unwrap_or_else(|e| panic!("case {case}: {e}\n{}", f.text()));
            let worst = on_the_curves(
                &set_points(&program),
                -1.0,
                std::slice::from_ref(&truth),
                0.06,
            );
            assert!(worst < 1e-9, "case {case}");
        }
    }
}

/// What a user gets wrong is refused with the file, line and instance: a curve out of
/// the XY plane (unless --project), a trim point off its curve, a curve entity not
/// read, an infinite line, a solid's edges only.
#[test]
fn cad_files_the_cut_cannot_follow_are_refused_at_their_line() {
    let job = curves_job(false);
    let err = |body: &str| {
        let text =
            format!("ISO-10303-21;\nHEADER;\nENDSEC;\nDATA;\n{body}\nENDSEC;\nEND-ISO-10303-21;\n");
        curves_program(&text, "part.stp", &job).unwrap_err()
    };
    let tilted = "#1=CARTESIAN_POINT('',(0.,0.,0.));\n#2=DIRECTION('',(1.,0.,0.));\n\
                  #3=DIRECTION('',(0.,0.,1.));\n#4=AXIS2_PLACEMENT_3D('',#1,#2,#3);\n\
                  #5=CIRCLE('',#4,5.);";
    let e = err(tilted);
    assert!(
        e.starts_with("part.stp:9: #5: plane: the curve leaves the XY plane"),
        "{e}"
    );
    let text =
        format!("ISO-10303-21;\nHEADER;\nENDSEC;\nDATA;\n{tilted}\nENDSEC;\nEND-ISO-10303-21;\n");
    let projected = CurvesJob {
        project: true,
        ..job.clone()
    };
    let (program, _) = curves_program(&text, "part.stp", &projected).unwrap();
    // The circle about X seen from above: a line from (0, 5) to (0, −5) and back.
    let cut: Vec<_> = set_points(&program)
        .into_iter()
        .filter(|p| p[2] == -1.0)
        .collect();
    assert!(cut
        .iter()
        .all(|p| p[0].abs() < 1e-9 && p[1].abs() <= 5.0 + 1e-9));
    let off = err(
        "#1=CARTESIAN_POINT('',(0.,0.,0.));\n#2=DIRECTION('',(1.,0.,0.));\n\
                   #3=VECTOR('',#2,1.);\n#4=LINE('',#1,#3);\n#5=CARTESIAN_POINT('',(3.,0.1,0.));\n\
                   #6=TRIMMED_CURVE('',#4,(#1),(#5),.T.,.CARTESIAN.);",
    );
    assert!(
        off.starts_with(
            "part.stp:10: #6: trim: trim_2's point (3, 0.1, 0) is 0.100000 mm from the curve"
        ),
        "{off}"
    );
    let e = err("#1=CARTESIAN_POINT('',(0.,0.,0.));\n#2=PARABOLA('',#1,2.);");
    assert!(
        e.contains("part.stp:6: #2: curve: PARABOLA is not a curve cnc cam curves reads"),
        "{e}"
    );
    let e = err(
        "#1=CARTESIAN_POINT('',(0.,0.,0.));\n#2=DIRECTION('',(1.,0.,0.));\n\
                 #3=VECTOR('',#2,1.);\n#4=LINE('',#1,#3);",
    );
    assert!(
        e.contains("part.stp:8: #4: curve: a LINE is infinite"),
        "{e}"
    );
    let e = err(
        "#1=CARTESIAN_POINT('',(0.,0.,0.));\n#2=DIRECTION('',(1.,0.,0.));\n\
                 #3=VECTOR('',#2,1.);\n#4=LINE('',#1,#3);\n#5=VERTEX_POINT('',#1);\n\
                 #6=EDGE_CURVE('',#5,#5,#4,.T.);",
    );
    assert!(
        e.contains("the file's 1 EDGE_CURVEs are a solid's edges"),
        "{e}"
    );
}

/// A file in inches and degrees: a circular arc run clockwise (sense .F.) and a closed,
/// unclamped (periodic) cubic B-spline trimmed across its seam. Every set-point on the
/// curves (converted to mm) to 1e-9 mm, each piece's ends reached.
#[test]
fn closed_curves_across_their_seam_in_inches_and_degrees() {
    let mut f = Part21(Vec::new());
    let mm = f.add("(LENGTH_UNIT() NAMED_UNIT(*) SI_UNIT(.MILLI.,.METRE.))".into());
    let inch_m = f.add(format!(
        "LENGTH_MEASURE_WITH_UNIT(LENGTH_MEASURE(25.4),#{mm})"
    ));
    let inch = f.add(format!(
        "(CONVERSION_BASED_UNIT('INCH',#{inch_m}) LENGTH_UNIT() NAMED_UNIT(*))"
    ));
    let rad = f.add("(NAMED_UNIT(*) PLANE_ANGLE_UNIT() SI_UNIT($,.RADIAN.))".into());
    let deg_m = f.add(format!(
        "PLANE_ANGLE_MEASURE_WITH_UNIT(PLANE_ANGLE_MEASURE(0.017453292519943295),#{rad})"
    ));
    let deg = f.add(format!(
        "(CONVERSION_BASED_UNIT('DEGREE',#{deg_m}) NAMED_UNIT(*) PLANE_ANGLE_UNIT())"
    ));
    f.add(format!(
        "(GEOMETRIC_REPRESENTATION_CONTEXT(2) GLOBAL_UNIT_ASSIGNED_CONTEXT((#{inch},#{deg})) REPRESENTATION_CONTEXT('',''))"
    ));
    let c = f.point([1.0, 1.0], 0.0);
    let place = f.add(format!("AXIS2_PLACEMENT_3D('',#{c},$,$)"));
    let circle = f.add(format!("CIRCLE('',#{place},0.5)"));
    f.add(format!(
        "TRIMMED_CURVE('',#{circle},(PARAMETER_VALUE(30.)),(PARAMETER_VALUE(300.)),.F.,.PARAMETER.)"
    ));
    // A closed cubic: 8 points, the last three repeating the first three, knots 0..=11.
    let ring: Vec<[f64; 2]> = (0..5)
        .map(|i| {
            let a = std::f64::consts::TAU * i as f64 / 5.0;
            [3.0 + 1.2 * a.cos() + 0.3 * (2.0 * a).sin(), 1.0 + a.sin()]
        })
        .collect();
    let pts: Vec<[f64; 2]> = (0..8).map(|i| ring[i % 5]).collect();
    let ids: Vec<String> = pts
        .iter()
        .map(|p| format!("#{}", f.point(*p, 0.0)))
        .collect();
    let spline = f.add(format!(
        "B_SPLINE_CURVE_WITH_KNOTS('',3,({}),.UNSPECIFIED.,.T.,.F.,(1,1,1,1,1,1,1,1,1,1,1,1),(0.,1.,2.,3.,4.,5.,6.,7.,8.,9.,10.,11.),.UNIFORM_KNOTS.)",
        ids.join(",")
    ));
    f.add(format!(
        "TRIMMED_CURVE('',#{spline},(PARAMETER_VALUE(7.25)),(PARAMETER_VALUE(3.5)),.T.,.PARAMETER.)"
    ));
    let deg1 = std::f64::consts::PI / 180.0;
    let mm_pts: Vec<[f64; 2]> = pts.iter().map(|p| [p[0] * 25.4, p[1] * 25.4]).collect();
    let spline_truth = |u0: f64, u1: f64| Truth::Spline {
        degree: 3,
        knots: (0..12).map(f64::from).collect(),
        pts: mm_pts.clone(),
        w: vec![1.0; 8],
        u0,
        u1,
    };
    let truths = [
        Truth::Conic {
            c: [25.4, 25.4],
            x: [12.7, 0.0],
            y: [0.0, 12.7],
            t0: -60.0 * deg1,
            t1: 30.0 * deg1,
        },
        spline_truth(7.25, 8.0),
        spline_truth(3.0, 3.5),
    ];
    for fanuc in [false, true] {
        let (program, summary) = curves_program(&f.text(), "inch.stp", &curves_job(fanuc)).unwrap();
        assert!(summary.starts_with("2 curves"), "{summary}");
        on_the_curves(&set_points(&program), -1.0, &truths, 0.06);
    }
}

/// A small file of `body` (instances from line 5 on), in mm and radians.
fn part(body: &str) -> String {
    format!("ISO-10303-21;\nHEADER;\nENDSEC;\nDATA;\n{body}\nENDSEC;\nEND-ISO-10303-21;\n")
}

/// The review's cases, each of which went wrong before it was mended: a reversed
/// composite segment over a trimmed arc (cut the other 270°), a trim parameter of 1e20
/// (never ended), a B-spline with an empty domain and trims a rounding either side of a
/// knot (panicked), a parameter and a point that disagree (the point was ignored),
/// weights a million apart (written out of the interpreter's range), a file name with
/// a parenthesis (broke the header comment).
#[test]
fn cad_curves_the_review_found_wrong() {
    let job = curves_job(false);
    let circle = "#1=CARTESIAN_POINT('',(10.,0.,0.));\n#2=AXIS2_PLACEMENT_3D('',#1,$,$);\n\
                  #3=CIRCLE('',#2,5.);\n";
    // The quarter from 0 to 90°, run backwards inside the composite: (10, 5) to (15, 0).
    let text = part(&format!(
        "{circle}#4=TRIMMED_CURVE('',#3,(PARAMETER_VALUE(0.)),(PARAMETER_VALUE(1.5707963267948966)),.T.,.PARAMETER.);\n\
         #5=COMPOSITE_CURVE_SEGMENT(.CONTINUOUS.,.F.,#4);\n#6=COMPOSITE_CURVE('',(#5),.F.);"
    ));
    let (program, _) = curves_program(&text, "part (2).stp", &job).unwrap();
    let quarter = Truth::Conic {
        c: [10.0, 0.0],
        x: [5.0, 0.0],
        y: [0.0, 5.0],
        t0: 0.0,
        t1: std::f64::consts::FRAC_PI_2,
    };
    on_the_curves(&set_points(&program), -1.0, &[quarter], 0.06);
    assert!(program.starts_with("(1 curves of part 2.stp:"), "{program}");
    let e = curves_program(
        &part(&format!(
            "{circle}#4=TRIMMED_CURVE('',#3,(PARAMETER_VALUE(1.E20)),(PARAMETER_VALUE(0.)),.T.,.PARAMETER.);"
        )),
        "part.stp",
        &job,
    )
    .unwrap_err();
    assert!(
        e.contains("part.stp:8: #4: trim: trim_1's parameter is beyond 1e9"),
        "{e}"
    );
    let pts = "#1=CARTESIAN_POINT('',(0.,0.,0.));\n#2=CARTESIAN_POINT('',(1.,1.,0.));\n\
               #3=CARTESIAN_POINT('',(2.,0.,0.));\n";
    let e = curves_program(
        &part(&format!(
            "{pts}#4=B_SPLINE_CURVE_WITH_KNOTS('',2,(#1,#2,#3),.UNSPECIFIED.,.F.,.F.,(1,1,2,1,1),(0.,1.,2.,3.,4.),.UNSPECIFIED.);"
        )),
        "part.stp",
        &job,
    )
    .unwrap_err();
    assert!(
        e.contains("#4: knots: the curve's domain, from knot 2 to knot 2, is empty"),
        "{e}"
    );
    // Trims a rounding either side of the inner knot 1: an empty piece, refused.
    let e = curves_program(
        &part(&format!(
            "{pts}#4=B_SPLINE_CURVE_WITH_KNOTS('',1,(#1,#2,#3),.UNSPECIFIED.,.F.,.F.,(2,1,2),(0.,1.,2.),.UNSPECIFIED.);\n\
             #5=TRIMMED_CURVE('',#4,(PARAMETER_VALUE(0.9999999999999999)),(PARAMETER_VALUE(1.0000000000000002)),.T.,.PARAMETER.);"
        )),
        "part.stp",
        &job,
    )
    .unwrap_err();
    assert!(e.contains("#5: trim:"), "{e}");
    // A degree file would say 90; this one says radians and means degrees.
    let e = curves_program(
        &part(&format!(
            "{circle}#4=CARTESIAN_POINT('',(10.,5.,0.));\n\
             #5=TRIMMED_CURVE('',#3,(PARAMETER_VALUE(0.)),(#4,PARAMETER_VALUE(90.)),.T.,.PARAMETER.);"
        )),
        "part.stp",
        &job,
    )
    .unwrap_err();
    assert!(
        e.contains("#5: trim: trim_2's parameter 90 and its point (10, 5, 0) are"),
        "{e}"
    );
    let weights = |w: &str| {
        curves_program(
            &part(&format!(
                "{pts}#4=(BOUNDED_CURVE() B_SPLINE_CURVE(2,(#1,#2,#3),.UNSPECIFIED.,.F.,.F.) \
                 B_SPLINE_CURVE_WITH_KNOTS((3,3),(0.,1.),.UNSPECIFIED.) CURVE() \
                 GEOMETRIC_REPRESENTATION_ITEM() RATIONAL_B_SPLINE_CURVE(({w})) REPRESENTATION_ITEM(''));"
            )),
            "part.stp",
            &job,
        )
    };
    let e = weights("0.3,300000.,0.3").unwrap_err();
    assert!(
        e.contains("#4: weights: its weights run from 0.3 to 300000"),
        "{e}"
    );
    let (program, _) = weights("0.3,149000.,0.3").unwrap();
    assert!(set_points(&program).len() > 10);
}
