//! T-spline surfaces from STEP-NC (issue #27, seed 003): the example part's patches
//! against the T-spline's own blending functions, a T-spline that is a tensor-product
//! NURBS against that NURBS given as `B_SPLINE_SURFACE_WITH_KNOTS`, and the errors a user
//! gets for a bad mesh.

use interpolator::engine::{BlockSource, Engine, Limits, TickState};
use interpreter::step::p21::Param;
use interpreter::step::{self, check::check_part};
use shared::nurbs::reference::piegl_tiller_surface;
use shared::protocol::CommandBlock;
use shared::Machine;

const PERIOD_NS: u64 = 1_000_000;

fn example(name: &str) -> String {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples")
        .join(name);
    std::fs::read_to_string(p).unwrap()
}

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// The id and text line of the file's one instance of `entity`.
fn instance_of(text: &str, entity: &str) -> (u64, usize) {
    let ex = step::parse(text).unwrap();
    let inst = ex
        .instances
        .values()
        .find(|i| i.records.iter().any(|r| r.name == entity))
        .unwrap_or_else(|| panic!("no {entity}"));
    (inst.id, inst.line as usize)
}

#[test]
fn the_example_parts_patches_are_its_t_spline() {
    // The reference: the surface the planner machines (the T-spline's Bézier
    // patches joined) against the T-spline evaluated from its blending functions, at
    // 3000 random (s, t): point, S_s and S_t within 1e-12 of the part's size (40 mm).
    let text = example("tspline-bump.stp");
    let (id, _) = instance_of(&text, "T_SPLINE_SURFACE");
    let ts = step::tspline::read(&step::parse(&text).unwrap(), id).unwrap();
    assert_eq!(ts.points.len(), 65);
    assert_eq!(ts.t_junctions(), 8);
    // Two T-regions round the notch at s 30..40, t 22.5..30 (seed 003: row strips
    // merged): all six cells of the rows below it, then the five left of it.
    let steps = step::read_part(&text).unwrap();
    let regions: Vec<_> = steps
        .iter()
        .map(|st| {
            let r = st.surface.t_spline.as_ref().unwrap();
            (r.region, r.regions, r.cells)
        })
        .collect();
    assert_eq!(regions, [(1, 2, (6, 5)), (2, 2, (5, 1))]);
    // Every weight in the file is 1, but the blending functions need not sum to 1: the
    // joined patches are rational, and `cnc check` says so.
    assert!(steps.iter().all(|st| st.surface.rational));
    // The feature is placed 10 mm along x and y.
    let offset = [10.0, 10.0, 0.0];
    let mut rng = Rng(0x7e57);
    let mut worst = 0.0f64;
    let mut in_notch = 0;
    for _ in 0..3000 {
        let (s, t) = (rng.next() * 40.0, rng.next() * 30.0);
        // The region whose domain holds (s, t); none in the notch.
        let Some(st) = steps.iter().find(|st| {
            let (u0, u1, v0, v1) = st.surface.geometry.domain();
            (u0..=u1).contains(&s) && (v0..=v1).contains(&t)
        }) else {
            assert!(s > 30.0 && t > 22.5, "({s}, {t}) in no region");
            in_notch += 1;
            continue;
        };
        let (p, ds, dt) = ts.eval(s, t);
        let r = piegl_tiller_surface(&st.surface.data(), s, t);
        for k in 0..3 {
            worst = worst
                .max((p[k] + offset[k] - r.p[k]).abs())
                .max((ds[k] - r.du[k]).abs())
                .max((dt[k] - r.dv[k]).abs());
        }
    }
    assert!(in_notch > 0);
    println!("worst difference {worst:e} mm");
    assert!(worst <= 1e-12 * 40.0, "worst difference {worst:e} mm");
}

/// `cubic-wave.stp` with its surface given as the T-spline of its whole knot lines.
fn cubic_wave_as_t_spline() -> String {
    let text = example("cubic-wave.stp");
    let ex = step::parse(&text).unwrap();
    let (id, line) = instance_of(&text, "B_SPLINE_SURFACE_WITH_KNOTS");
    let rec = &ex.instances[&id].records[0];
    let Param::List(rows) = &rec.params[3] else {
        panic!("control_points_list")
    };
    let mut refs = Vec::new();
    let mut anchors = Vec::new();
    for (i, row) in rows.iter().enumerate() {
        let Param::List(row) = row else { panic!() };
        for (j, p) in row.iter().enumerate() {
            let Param::Ref(r) = p else { panic!() };
            refs.push(format!("#{r}"));
            // Anchors from line 3 (1-based): the two outer lines carry no points.
            anchors.push(format!("({},{})", i + 3, j + 3));
        }
    }
    let n = rows.len(); // 8 x 8, knots 0,0,0,0,.2,.4,.6,.8,1,1,1,1 both ways
    assert_eq!(n, 8);
    let lines = "(0.,0.,0.,0.,0.2,0.4,0.6,0.8,1.,1.,1.,1.)";
    let segs: Vec<String> = (3..=n + 2).map(|l| format!("({l},3,{})", n + 2)).collect();
    let segs = format!("({})", segs.join(","));
    let t_spline = format!(
        "#{id}=T_SPLINE_SURFACE('cubic wave',3,3,{lines},{lines},{segs},{segs},({}),$,({}),$,$);",
        refs.join(","),
        anchors.join(",")
    );
    // The surface instance is one line in the file; replace it in place, so every line
    // number stays the same.
    let mut out: Vec<String> = text.lines().map(str::to_string).collect();
    assert!(out[line - 1].starts_with(&format!("#{id}=B_SPLINE_SURFACE_WITH_KNOTS")));
    out[line - 1] = t_spline;
    out.join("\n") + "\n"
}

struct Slice(Vec<CommandBlock>, usize);
impl BlockSource for Slice {
    fn next_block(&mut self) -> Option<CommandBlock> {
        let b = self.0.get(self.1).copied();
        self.1 += usize::from(b.is_some());
        b
    }
}

fn set_points(text: &str) -> Vec<[f64; 3]> {
    let machine = Machine::default();
    let (blocks, _) = interpreter::surface_blocks::part_blocks(text, &machine, PERIOD_NS).unwrap();
    let mut engine = Engine::new(Limits::new(&machine, PERIOD_NS), [0.0; 3]);
    let mut src = Slice(blocks, 0);
    let mut out = Vec::new();
    loop {
        let t = engine.tick(&mut src).unwrap();
        out.push(t.pos_mm);
        if t.state == TickState::Done {
            return out;
        }
    }
}

#[test]
fn a_t_spline_that_is_a_nurbs_runs_as_that_nurbs() {
    // The same number of cycles and the same set-points, cycle by cycle, within 1e-6 mm
    // (0.001 µm, the accuracy the stack claims for set-points on the curve): the patches'
    // points come from the extraction here and from knot insertion for the NURBS, which
    // round differently in the last bits; the planner's finite differences on the tool
    // point's path (`shared::path::tool_rate2`) turn that into junction speeds a few
    // 1e-8 apart, and the engine carries it along the 260 s run (1.3e-7 mm at most when
    // this was written).
    let nurbs = example("cubic-wave.stp");
    let tspline = cubic_wave_as_t_spline();
    let check = check_part("wave.stp", &tspline, &Machine::default()).unwrap();
    assert!(
        check.contains("T-spline, degree 3, 64 control points, 0 T-junctions"),
        "{check}"
    );
    let a = set_points(&nurbs);
    let b = set_points(&tspline);
    assert_eq!(a.len(), b.len(), "cycles");
    let worst = a
        .iter()
        .zip(&b)
        .flat_map(|(p, q)| (0..3).map(move |k| (p[k] - q[k]).abs()))
        .fold(0.0f64, f64::max);
    println!(
        "{} cycles, worst set-point difference {worst:e} mm",
        a.len()
    );
    assert!(worst <= 1e-6, "worst set-point difference {worst:e} mm");
}

#[test]
fn a_bad_t_mesh_is_refused_with_its_line_and_point() {
    let text = example("tspline-bump.stp");
    let (id, line) = instance_of(&text, "T_SPLINE_SURFACE");
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let src = &lines[line - 1];
    // Give the point at anchor (5, 6) (s = 10, t = 11.25, just left of the short line
    // s = 15) s knots that skip the short line.
    let ex = step::parse(&text).unwrap();
    let rec = &ex.instances[&id].records[0];
    let Param::List(anchors) = &rec.params[9] else {
        panic!()
    };
    let k = anchors
        .iter()
        .position(|a| matches!(a, Param::List(l) if l == &[Param::Int(5), Param::Int(6)]))
        .unwrap();
    let Param::List(sk) = &rec.params[10] else {
        panic!()
    };
    let Param::List(mine) = &sk[k] else { panic!() };
    let have: Vec<f64> = mine
        .iter()
        .map(|x| match x {
            Param::Real(v) => *v,
            _ => panic!(),
        })
        .collect();
    assert_eq!(have, [0.0, 0.0, 10.0, 15.0, 20.0]);
    // Replace that entry of s_local_knots (attribute 11) in the text.
    let attrs = src.find('(').unwrap();
    let (from, to) = element(src, attrs, 10);
    let (from, to) = element(&src[..to], from, k);
    lines[line - 1] = format!("{}(0.0,0.0,10.0,20.0,30.0){}", &src[..from], &src[to..]);
    let bad = lines.join("\n");
    let err = check_part("bump.stp", &bad, &Machine::default()).unwrap_err();
    let want = format!(
        "bump.stp:{line}: #{id}: local knots: control point {} (#",
        k + 1
    );
    assert!(err.contains(&want), "{err}");
    assert!(
        err.contains("s knots (0, 0, 10, 20, 30) disagree with the T-mesh's rays from anchor (5, 6), which give (0, 0, 10, 15, 20)"),
        "{err}"
    );
    // A degree the reader does not take.
    let deg = text.replace(
        "T_SPLINE_SURFACE('t-spline bump',3,3,",
        "T_SPLINE_SURFACE('t-spline bump',2,3,",
    );
    let err = check_part("bump.stp", &deg, &Machine::default()).unwrap_err();
    assert!(
        err.contains(&format!("bump.stp:{line}: #{id}: degree: s_degree is 2; T-spline surfaces are read for degree 3")),
        "{err}"
    );
}

/// The byte range of the `n`-th element (0-based) of the list that opens at `open`.
fn element(text: &str, open: usize, n: usize) -> (usize, usize) {
    let b = text.as_bytes();
    assert_eq!(b[open], b'(');
    let (mut depth, mut k, mut start) = (0, 0, open + 1);
    for (i, &c) in b.iter().enumerate().skip(open) {
        match c {
            b'(' => depth += 1,
            b')' | b',' if depth == 1 => {
                if k == n {
                    return (start, i);
                }
                k += 1;
                start = i + 1;
                if c == b')' {
                    break;
                }
            }
            b')' => depth -= 1,
            _ => {}
        }
    }
    panic!("no element {n}")
}

#[test]
fn plane_cc_passes_cut_each_t_region_in_planes() {
    // The example with PLANE_CC_STRATEGY: planes normal to y (its sideward direction,
    // the third ratio read as 0). Each T-region's patches are intersected with the
    // planes; every contact point of every pass lies in its plane within the chordal
    // tolerance (1 µm) and on the T-spline itself.
    let text = example("tspline-bump.stp");
    let uv = "#81=UV_STRATEGY(.ZIGZAG.,.CLIMB.,#78,$,#79,#80);";
    assert!(text.contains(uv));
    let plane = text.replace(uv, "#81=PLANE_CC_STRATEGY(.ZIGZAG.,.CLIMB.,#78,$,#80);");
    let planned = step::check::plan_part(&plane).unwrap();
    assert_eq!(planned.len(), 2, "one pass set per T-region");
    let (id, _) = instance_of(&plane, "T_SPLINE_SURFACE");
    let ts = step::tspline::read(&step::parse(&plane).unwrap(), id).unwrap();
    let mut points = 0;
    for (st, path) in &planned {
        let path = path.plane().expect("a plane path");
        assert!(!path.passes.is_empty());
        let surf = st.surface.data();
        for pass in &path.passes {
            for &(u, v) in &pass.uv {
                let p = piegl_tiller_surface(&surf, u, v).p;
                let n = path.normal;
                let off = n[0] * p[0] + n[1] * p[1] + n[2] * p[2] - pass.level_mm;
                assert!(off.abs() <= 1e-3, "{off} mm off its plane");
                // The T-spline in the file's coordinates; the feature sits at (10, 10, 0).
                let (q, _, _) = ts.eval(u, v);
                let d = [p[0] - 10.0 - q[0], p[1] - 10.0 - q[1], p[2] - q[2]];
                assert!(d.iter().all(|x| x.abs() < 1e-9), "{d:?} at ({u}, {v})");
                points += 1;
            }
        }
    }
    assert!(points > 1000, "{points}");
    // And it plans into blocks, both regions joined with lifts.
    let (blocks, _) =
        interpreter::surface_blocks::part_blocks(&plane, &Machine::default(), PERIOD_NS).unwrap();
    assert!(blocks.iter().filter(|b| b.is_surface()).count() > 100);
}
