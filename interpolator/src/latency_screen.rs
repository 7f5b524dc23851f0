//! What `cnc latency-test` shows while it measures, as LinuxCNC's latency-test does: the
//! running worst wake-up lateness (the figure its verdict is made from), the current
//! min, mean and count, and a text histogram of the lateness so far.
//!
//! On a terminal the figures are redrawn in place a few times a second (ANSI cursor moves,
//! only there); into a pipe or a file one plain progress line goes out about once a second,
//! and one more with the final figures, so a log shows the run's course without escape
//! codes. The figures come from [`crate::rt::latency::Live`], which the measuring thread
//! fills with plain atomic stores: drawing never touches it.

use crate::rt::latency::{live_bin_bounds, us, verdict, LiveFigures, LIVE_BINS};
use std::io::Write;
use std::time::Duration;

/// How often the terminal view is redrawn.
pub const TERMINAL_EVERY: Duration = Duration::from_millis(250);
/// How often a progress line goes into a pipe or a file.
pub const PLAIN_EVERY: Duration = Duration::from_secs(1);

/// The width of the longest histogram bar, in characters.
pub const BAR_WIDTH: usize = 40;

/// A LinuxCNC band in words, by its id from [`verdict`].
fn band_words(id: &str) -> &'static str {
    match id {
        "very_good" => "very good",
        "good" => "good",
        "needs_care" => "needs care",
        _ => "unusable",
    }
}

/// A bin edge: whole µs below a millisecond, whole ms from there.
fn edge(ns: u64) -> (u64, &'static str) {
    if ns < 1_000_000 {
        (ns / 1000, "µs")
    } else {
        (ns / 1_000_000, "ms")
    }
}

/// The range of live bin `i` in words: `0–5 µs`, `500 µs–1 ms`, `≥ 5 ms`.
pub fn bin_label(i: usize) -> String {
    let (lo, hi) = live_bin_bounds(i);
    let (l, lu) = edge(lo);
    match hi.map(edge) {
        None => format!("≥ {l} {lu}"),
        Some((h, hu)) if hu == lu => format!("{l}–{h} {hu}"),
        Some((h, hu)) => format!("{l} {lu}–{h} {hu}"),
    }
}

/// The running figures in one line: how far the test is, the wake-ups so far, their
/// lateness (min, mean, max with its band) and how many came later than a whole period.
pub fn live_line(f: &LiveFigures, period_ns: u64, seconds: f64) -> String {
    let done_s = (f.wakeups * period_ns) as f64 * 1e-9;
    if f.wakeups == 0 {
        return format!("{done_s:.1} s of {seconds:.1} s: no wake-up yet");
    }
    format!(
        "{done_s:.1} s of {seconds:.1} s: {} wake-ups, lateness min {}, mean {}, max {} ({}); {} later than the period",
        f.wakeups,
        us(f.min_ns),
        us(f.mean_ns.round() as u64),
        us(f.max_ns),
        band_words(verdict(f.max_ns).0),
        f.later_than_period
    )
}

/// The histogram as text, one line per bin from the lowest (always all of them, so the
/// view keeps its height): the bin's range, its count, a bar and the bin's band. Bars are
/// on a log scale, as in LinuxCNC's latency histogram: the wake-ups pile up in one or two
/// bins, and a linear bar would hide the rare late ones that decide the verdict. A bin
/// with anything in it gets at least one `#`.
pub fn histogram_lines(bins: &[u64; LIVE_BINS]) -> Vec<String> {
    let top = bins.iter().copied().max().unwrap_or(0);
    let scale = ((top + 1) as f64).ln();
    (0..LIVE_BINS)
        .map(|i| {
            let n = bins.get(i).copied().unwrap_or(0);
            let bar = if n == 0 || scale <= 0.0 {
                0
            } else {
                let len = ((n + 1) as f64).ln() / scale * BAR_WIDTH as f64;
                (len.round() as usize).clamp(1, BAR_WIDTH)
            };
            format!(
                "{:>12} {n:>10} |{:<BAR_WIDTH$}| {}",
                bin_label(i),
                "#".repeat(bar),
                band_words(verdict(live_bin_bounds(i).0).0)
            )
        })
        .collect()
}

/// Where the live figures go: a terminal (redrawn in place) or a pipe or file (a line
/// now and then).
pub struct Screen<W: Write> {
    out: W,
    terminal: bool,
    period_ns: u64,
    seconds: f64,
    /// Lines drawn last time on a terminal, to move back over.
    drawn: usize,
}

impl<W: Write> Screen<W> {
    pub fn new(out: W, terminal: bool, period_ns: u64, seconds: f64) -> Self {
        Screen {
            out,
            terminal,
            period_ns,
            seconds,
            drawn: 0,
        }
    }

    /// How often [`Screen::show`] should be called.
    pub fn every(&self) -> Duration {
        if self.terminal {
            TERMINAL_EVERY
        } else {
            PLAIN_EVERY
        }
    }

    /// Shows `f`: on a terminal over the last view, elsewhere as one more line. A failed
    /// write (a closed pipe) is ignored: it must not end the measurement.
    pub fn show(&mut self, f: &LiveFigures) {
        let line = live_line(f, self.period_ns, self.seconds);
        let mut text = String::new();
        if self.terminal {
            // Two lines of under 80 columns: a wrapped line would throw the redraw off
            // (the cursor goes back by lines, not screen rows).
            let (progress, figures) = match line.split_once(", lateness ") {
                Some((p, f)) => match f.split_once("; ") {
                    Some((lat, later)) => (format!("{p}, {later}"), format!("  lateness {lat}")),
                    None => (p.to_string(), format!("  lateness {f}")),
                },
                None => (line, String::new()),
            };
            let mut lines = vec![
                progress,
                figures,
                format!(
                    "{:>12} {:>10}  (bars on a log scale)",
                    "lateness", "wake-ups"
                ),
            ];
            lines.extend(histogram_lines(&f.bins));
            if self.drawn > 0 {
                // Back to the start of the first line drawn last time.
                text.push_str(&format!("\x1b[{}F", self.drawn));
            }
            for l in &lines {
                text.push_str("\x1b[2K");
                text.push_str(l);
                text.push('\n');
            }
            self.drawn = lines.len();
        } else {
            text.push_str("latency-test ");
            text.push_str(&line);
            text.push('\n');
        }
        let _ = self.out.write_all(text.as_bytes());
        let _ = self.out.flush();
    }

    pub fn into_inner(self) -> W {
        self.out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn figures(bins: [u64; LIVE_BINS]) -> LiveFigures {
        LiveFigures {
            wakeups: bins.iter().sum(),
            min_ns: 2_100,
            max_ns: 137_000,
            mean_ns: 47_400.0,
            later_than_period: 0,
            bins,
        }
    }

    #[test]
    fn bins_are_named_by_their_range() {
        let labels: Vec<String> = (0..LIVE_BINS).map(bin_label).collect();
        assert_eq!(
            labels,
            [
                "0–5 µs",
                "5–10 µs",
                "10–20 µs",
                "20–50 µs",
                "50–100 µs",
                "100–200 µs",
                "200–500 µs",
                "500 µs–1 ms",
                "1–2 ms",
                "2–5 ms",
                "≥ 5 ms"
            ]
        );
    }

    #[test]
    fn the_histogram_has_a_line_per_bin_with_log_scaled_bars_and_bands() {
        let mut bins = [0u64; LIVE_BINS];
        bins[1] = 9_000;
        bins[3] = 990;
        bins[5] = 9;
        bins[10] = 1;
        let lines = histogram_lines(&bins);
        assert_eq!(lines.len(), LIVE_BINS);
        let bar = |l: &str| l.matches('#').count();
        assert_eq!(bar(&lines[1]), BAR_WIDTH);
        assert_eq!(bar(&lines[0]), 0);
        // Log scale: 990 of 9000 is far more than a ninth of the bar, and the single
        // late wake-up still shows.
        assert!(
            bar(&lines[3]) > 25 && bar(&lines[3]) < BAR_WIDTH,
            "{}",
            lines[3]
        );
        assert!(bar(&lines[5]) < bar(&lines[3]));
        assert_eq!(bar(&lines[10]), 3);
        assert_eq!(
            lines[3],
            format!(
                "{:>12} {:>10} |{:<40}| good",
                "20–50 µs",
                990,
                "#".repeat(bar(&lines[3]))
            )
        );
        assert!(lines[0].ends_with("| very good"));
        assert!(lines[6].ends_with("| needs care"));
        assert!(lines[7].ends_with("| unusable"));
        // Nothing recorded: every bin empty, no bar, no division by zero.
        assert!(histogram_lines(&[0; LIVE_BINS])
            .iter()
            .all(|l| !l.contains('#')));
    }

    #[test]
    fn the_live_line_says_how_far_and_how_late() {
        let mut bins = [0u64; LIVE_BINS];
        bins[4] = 2_000;
        let f = figures(bins);
        assert_eq!(
            live_line(&f, 1_000_000, 10.0),
            "2.0 s of 10.0 s: 2000 wake-ups, lateness min 2.1 µs, mean 47 µs, max 137 µs (needs care); 0 later than the period"
        );
        assert_eq!(
            live_line(&LiveFigures::default(), 1_000_000, 10.0),
            "0.0 s of 10.0 s: no wake-up yet"
        );
    }

    #[test]
    fn a_pipe_gets_plain_lines_and_a_terminal_a_view_redrawn_in_place() {
        let mut bins = [0u64; LIVE_BINS];
        bins[0] = 500;
        let f = figures(bins);
        let mut plain = Screen::new(Vec::new(), false, 1_000_000, 10.0);
        assert_eq!(plain.every(), PLAIN_EVERY);
        plain.show(&f);
        plain.show(&f);
        let text = String::from_utf8(plain.into_inner()).unwrap();
        assert_eq!(text.lines().count(), 2);
        assert!(
            text.starts_with("latency-test 0.5 s of 10.0 s: 500 wake-ups"),
            "{text}"
        );
        assert!(!text.contains('\u{1b}'), "escape codes in a pipe: {text:?}");

        let mut tty = Screen::new(Vec::new(), true, 1_000_000, 10.0);
        assert_eq!(tty.every(), TERMINAL_EVERY);
        tty.show(&f);
        tty.show(&f);
        let text = String::from_utf8(tty.into_inner()).unwrap();
        // The progress, the figures, the header and the bins.
        let height = 3 + LIVE_BINS;
        assert_eq!(text.lines().count(), 2 * height);
        // Each line fits an 80-column terminal (a wrapped one would throw the redraw
        // off: the cursor goes back by lines, not screen rows).
        for l in text.lines() {
            let shown = l
                .replace("\x1b[2K", "")
                .replace(&format!("\x1b[{height}F"), "");
            assert!(
                shown.chars().count() <= 80,
                "{} columns: {shown}",
                shown.chars().count()
            );
        }
        // The second view starts by moving up over the first, which did not.
        assert_eq!(text.matches(&format!("\x1b[{height}F")).count(), 1);
        assert!(text.starts_with("\x1b[2K"), "{text:?}");
        assert!(text.contains("0–5 µs        500 |"), "{text}");
    }
}
