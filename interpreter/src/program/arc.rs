//! Circular and helical moves (G2, G3) in the three planes, centre and radius forms.

use super::{LineWords, Move, State, OFFSETS};
use crate::parse::Diagnostic;
use std::f64::consts::SQRT_2;

/// How far the end of a centre-form arc may be off the circle its centre gives, as
/// LinuxCNC's rs274ngc allows it (`interp_internal.hh`, `arc_data_ijk`): the radii at
/// the start and the end may differ by this much in the program's units (mm here)...
const CENTRE_TOL_MM: f64 = 0.02 * SQRT_2;
/// ... or by this much in inches, in `G20`...
const CENTRE_TOL_INCH: f64 = 0.002 * SQRT_2;
/// ... or by a thousandth of the larger radius, up to a hundred times the above.
const CENTRE_TOL_REL: f64 = 0.001;

/// How much shorter than half the chord a radius-form arc's `R` may be (LinuxCNC's
/// `RADIUS_TOLERANCE_INCH`, 0.00005 in, in mm for both units).
const R_FORM_TOL_MM: f64 = 0.00005 * 25.4;

/// Most full turns one arc may make (`P`). LinuxCNC sets no limit, but every turn
/// becomes blocks: without one, `P99999999` would keep the checker busy for hours. Ten
/// thousand turns is a thread milled far longer than any machine's Z travel allows.
const MAX_TURNS: u32 = 10_000;

pub(super) fn arc(
    st: &State,
    lw: &LineWords,
    to: [f64; 3],
    ccw: bool,
    unit: f64,
    col: u32,
) -> Result<Move, Diagnostic> {
    let (a, b) = st.plane.axes();
    let n = st.plane.normal();
    let from = st.pos;
    if let Some(w) = lw.get(OFFSETS[n]) {
        return Err(lw.err(
            "arc",
            w.col,
            format!(
                "{} offset given for an arc in the {:?} plane",
                OFFSETS[n], st.plane
            ),
        ));
    }
    let turns = match lw.get('P') {
        None => 1,
        Some(p) if (1.0..=MAX_TURNS as f64).contains(&p.value) && p.value.fract() == 0.0 => {
            p.value as u32
        }
        Some(p) => {
            return Err(lw.err(
                "arc",
                p.col,
                format!("arc turn count P must be a whole number from 1 to {MAX_TURNS}"),
            ))
        }
    };
    let (da, db) = (to[a] - from[a], to[b] - from[b]);
    let chord = (da * da + db * db).sqrt();
    let mut center = [0.0; 3];
    center[n] = from[n];
    // Where the arc ends: the programmed end, but for a short chord (below).
    let mut end = to;
    if let Some(rw) = lw.get('R') {
        if lw.get(OFFSETS[a]).is_some() || lw.get(OFFSETS[b]).is_some() {
            return Err(lw.err(
                "arc",
                rw.col,
                "arc has both R and centre offsets; give one form",
            ));
        }
        let r = rw.value * unit;
        if chord < 1e-9 {
            return Err(lw.err("arc", rw.col, "R-form arc with its end at its start: a full circle needs the centre form (I, J, K)"));
        }
        let half = chord / 2.0;
        if r.abs() < half - R_FORM_TOL_MM {
            return Err(lw.err(
                "arc",
                rw.col,
                format!(
                    "arc radius {:.4} mm is too small to reach an end point {:.4} mm away",
                    r.abs(),
                    chord
                ),
            ));
        }
        let h = (r * r - half * half).max(0.0).sqrt();
        // Centre on the left of the chord for a short counter-clockwise arc; R < 0 asks
        // for the long way round, which puts it on the other side.
        let side = if ccw { 1.0 } else { -1.0 } * r.signum();
        let (ua, ub) = (da / chord, db / chord);
        center[a] = from[a] + da / 2.0 - side * h * ub;
        center[b] = from[b] + db / 2.0 + side * h * ua;
    } else {
        let (ia, ib) = (lw.value(OFFSETS[a]), lw.value(OFFSETS[b]));
        if ia.is_none() && ib.is_none() {
            return Err(lw.err(
                "arc",
                col,
                format!(
                    "arc needs R or a centre ({} and {})",
                    OFFSETS[a], OFFSETS[b]
                ),
            ));
        }
        let (ia, ib) = (ia.unwrap_or(0.0) * unit, ib.unwrap_or(0.0) * unit);
        let (ca, cb) = if st.arc_absolute {
            (ia, ib)
        } else {
            (from[a] + ia, from[b] + ib)
        };
        // The programmed centre, before its radii are squared (1e200 would overflow
        // them to infinity, and every comparison below would pass).
        let mut programmed = center;
        programmed[a] = ca;
        programmed[b] = cb;
        let centre_col = lw
            .get(OFFSETS[a])
            .or_else(|| lw.get(OFFSETS[b]))
            .map_or(col, |w| w.col);
        super::within_reach(lw, centre_col, "the arc's centre", programmed)?;
        let r0 = ((from[a] - ca).powi(2) + (from[b] - cb).powi(2)).sqrt();
        let r1 = ((to[a] - ca).powi(2) + (to[b] - cb).powi(2)).sqrt();
        if r0 < 1e-9 {
            return Err(lw.err("arc", col, "arc centre coincides with its start point"));
        }
        let diff = (r1 - r0).abs();
        let tol = if st.inch {
            CENTRE_TOL_INCH * 25.4
        } else {
            CENTRE_TOL_MM
        };
        if diff > 100.0 * tol || (diff > tol && diff > CENTRE_TOL_REL * r0.max(r1)) {
            return Err(lw.err("arc",
                col,
                format!("radius to the end of the arc ({r1:.4} mm) differs from the radius to its start ({r0:.4} mm)"),
            ));
        }
        center[a] = ca;
        center[b] = cb;
        if chord >= 1e-9 {
            // Within tolerance: the exact circle through both programmed end points has
            // its centre on the chord's bisector; the nearest such centre is
            // `(r0² − r1²)/2·chord` along the chord from the programmed one. Taken where
            // that is within the radius tolerance (nearly every arc: a chord as long as
            // the radius moves the centre by at most the radii's difference), which on a
            // circle of 10 mm or less is 28 µm (72 µm in `G20`), else 0.1 %.
            let (ma, mb) = (from[a] + da / 2.0, from[b] + db / 2.0);
            let (na, nb) = (-db / chord, da / chord);
            let t = (ca - ma) * na + (cb - mb) * nb;
            let (pa, pb) = (ma + t * na, mb + t * nb);
            let moved = (pa - ca).hypot(pb - cb);
            if moved <= tol.max(CENTRE_TOL_REL * r0) {
                center[a] = pa;
                center[b] = pb;
            } else {
                // A short chord (a full circle whose end is its start but for the
                // rounding of the numbers, a tiny arc on a large radius): the bisector
                // is no guide, and the centre on it can be as far off as the radius (a
                // different circle). The programmed circle is kept and the arc ends on
                // it, at the programmed end's angle: `|r1 − r0|`, within the tolerance,
                // from that end. LinuxCNC ends exactly there, on a spiral from r0 to r1.
                end[a] = ca + (to[a] - ca) * r0 / r1;
                end[b] = cb + (to[b] - cb) * r0 / r1;
            }
        }
    }
    let centre_col = lw
        .get('R')
        .or_else(|| lw.get(OFFSETS[a]))
        .or_else(|| lw.get(OFFSETS[b]))
        .map_or(col, |w| w.col);
    super::within_reach(lw, centre_col, "the arc's centre", center)?;
    Ok(Move::Arc {
        line: lw.line,
        from,
        to: end,
        center,
        plane: st.plane,
        ccw,
        turns,
        feed: st.feed,
    })
}
