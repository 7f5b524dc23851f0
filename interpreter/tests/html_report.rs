//! The HTML run report (`interpreter::html`) over real run directories: the circle, the
//! built-in demo and a LinuxCNC NURBS program are run through the real three-process
//! stack under the simulated clock, then rendered, and the page's content is checked
//! against `report.json`. Damaged run directories must give a clear error or a page that
//! names what is missing, never a panic.

use interpreter::html::{self, HtmlError};
use serde_json::Value;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

const CIRCLE: &str = "G21 G17 G90\nG0 X10 Y0\nG3 X10 Y0 I-10 J0 F3000\nM2\n";

fn scratch(name: &str) -> PathBuf {
    let d =
        Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("html-{name}-{}", std::process::id()));
    let _ = fs::remove_dir_all(&d);
    fs::create_dir_all(&d).unwrap();
    d
}

/// `cnc run --clock sim` into `out`; `program` None runs the built-in demo.
fn run_sim(program: Option<&Path>, out: &Path) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_cnc"));
    cmd.args(["run", "--clock", "sim", "--out"]).arg(out);
    if let Some(p) = program {
        cmd.arg(p);
    }
    let o = cmd.output().unwrap();
    assert!(
        o.status.success(),
        "cnc run failed: {}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

fn circle_run(name: &str) -> PathBuf {
    let d = scratch(name);
    let prog = d.join("circle.ngc");
    fs::write(&prog, CIRCLE).unwrap();
    let run = d.join("run");
    run_sim(Some(&prog), &run);
    run
}

fn report(run: &Path) -> Value {
    serde_json::from_str(&fs::read_to_string(run.join("report.json")).unwrap()).unwrap()
}

fn copy_dir(from: &Path, to: &Path) {
    fs::create_dir_all(to).unwrap();
    for e in fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        fs::copy(e.path(), to.join(e.file_name())).unwrap();
    }
}

/// The cell of the summary that shows `key`, up to its closing tag.
fn cell<'a>(page: &'a str, key: &str) -> &'a str {
    let tag = format!("data-key=\"{key}\">");
    let at = page
        .find(&tag)
        .unwrap_or_else(|| panic!("no summary cell {key}"))
        + tag.len();
    let end = page[at..].find("</td>").unwrap() + at;
    &page[at..end]
}

/// Every figure of the summary equals report.json's, as the page rounds it.
fn check_summary(page: &str, rep: &Value) {
    let f = |k: &str| rep[k].as_f64().unwrap();
    assert_eq!(cell(page, "time_s"), format!("{:.3} s", f("time_s")));
    assert_eq!(
        cell(page, "path_length_mm"),
        format!("{:.3} mm", f("path_length_mm"))
    );
    assert_eq!(
        cell(page, "avg_feed_mm_per_min"),
        format!("{:.1} mm/min", f("avg_feed_mm_per_min"))
    );
    assert_eq!(
        cell(page, "peak_feed_mm_per_min"),
        format!("{:.1} mm/min", f("peak_feed_mm_per_min"))
    );
    let axes = rep["max_following_error_axis_um"].as_array().unwrap();
    assert_eq!(
        cell(page, "max_following_error_um"),
        format!(
            "{:.2} µm (X {:.2}, Y {:.2}, Z {:.2} µm)",
            f("max_following_error_um"),
            axes[0].as_f64().unwrap(),
            axes[1].as_f64().unwrap(),
            axes[2].as_f64().unwrap()
        )
    );
    assert_eq!(
        cell(page, "cycles"),
        rep["cycles"].as_u64().unwrap().to_string()
    );
    assert_eq!(
        cell(page, "blocks"),
        rep["blocks"].as_u64().unwrap().to_string()
    );
    let period_us = rep["period_ns"].as_u64().unwrap() / 1000;
    assert!(cell(page, "period_ns").starts_with(&format!("{period_us} µs")));
    assert!(cell(page, "program").contains(rep["program"].as_str().unwrap()));
    if rep["outcome"] == "done" {
        assert!(cell(page, "outcome").contains("completed"));
    }
    if rep["clock"] == "sim" {
        assert_eq!(cell(page, "misses"), "not measured (simulated clock)");
        assert!(page.contains("id=\"timing-not-measured\""));
        assert!(!page.contains("id=\"pct-plot\""));
    }
}

/// Each plot is there with its title and the axis labels with their units.
fn check_plots(page: &str) {
    for (id, labels) in [
        ("path-plot", &["(mm)"][..]),
        ("feed-plot", &["time (s)", "feed (mm/min)"][..]),
        (
            "acc-plot",
            &["time (s)", "acceleration (mm/s²)", "path_acc_mm_per_s2"][..],
        ),
        ("jerk-plot", &["time (s)", "jerk (mm/s³)"][..]),
        ("ferr-plot", &["time (s)", "error (µm)"][..]),
    ] {
        let at = page
            .find(&format!("id=\"{id}\""))
            .unwrap_or_else(|| panic!("no {id}"));
        let svg = &page[at..at + page[at..].find("</svg>").unwrap()];
        assert!(
            svg.contains(&format!("<title id=\"{id}-t\">")),
            "{id}: no title"
        );
        for l in labels {
            assert!(svg.contains(l), "{id}: no `{l}`");
        }
        assert!(svg.contains("<polyline"), "{id}: no data");
    }
    // Self-contained: no script, nothing fetched.
    assert!(!page.contains("<script"));
    assert!(!page.contains("http://") && !page.contains("https://"));
    assert!(page.len() < 5_000_000);
}

#[test]
fn circle_page_matches_report_and_has_a_roundness_plot() {
    let run = circle_run("circle");
    let path = html::write(&run, None).unwrap();
    assert_eq!(path, run.join("report.html"));
    let page = fs::read_to_string(&path).unwrap();
    let rep = report(&run);
    check_summary(&page, &rep);
    check_plots(&page);
    assert!(
        !page.contains("id=\"problems\""),
        "an intact run lists no problems"
    );
    assert!(page.contains("XY plane"));
    // The roundness plot with its figure, about the programmed centre and radius.
    assert!(page.contains("id=\"polar-plot\""));
    assert!(page.contains("id=\"circularity\">"));
    assert!(page.contains("10.0000 mm"), "best-fit radius");
    assert!(page.contains("X 0.0000 mm, Y 0.0000 mm"), "best-fit centre");
    // Source-line tooltips on the path, the rapid drawn dashed, start and end marked.
    assert!(page.contains("<title>line 3: G3 X10 Y0 I-10 J0 F3000 |"));
    assert!(page.contains("class=\"rapid\""));
    assert!(page.contains("<title>start</title>") && page.contains("<title>end</title>"));
    // Written elsewhere on request.
    let other = run.join("elsewhere.html");
    assert_eq!(html::write(&run, Some(&other)).unwrap(), other);
    assert_eq!(fs::read_to_string(other).unwrap(), page);
}

#[test]
fn demo_page_rounds_its_full_circle_and_a_linuxcnc_page_has_none() {
    let d = scratch("open");
    let demo = d.join("demo");
    run_sim(None, &demo);
    let page = html::render(&demo).unwrap();
    check_summary(&page, &report(&demo));
    check_plots(&page);
    // The demo's full circle (line 23, `G3 X30 Y20 I-10 J0`, the bore's finishing pass)
    // gets the roundness plot.
    assert!(page.contains("id=\"polar-plot\""));
    assert!(
        report(&demo)["roundness"].is_object(),
        "report.json has the figure too"
    );
    assert!(
        page.contains("XY plane (projection)"),
        "the demo also moves in Z"
    );

    let prog =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/peers/linuxcnc/g5_butterfly-yz.ngc");
    let bfly = d.join("butterfly");
    run_sim(Some(&prog), &bfly);
    let page = html::render(&bfly).unwrap();
    check_summary(&page, &report(&bfly));
    check_plots(&page);
    assert!(!page.contains("id=\"polar-plot\""));
    assert!(
        page.contains("YZ plane"),
        "a G19 program is drawn in its own plane"
    );
    assert!(
        page.contains("<title>line ") && page.contains("G5.2"),
        "NURBS tooltips name the G5.2 line"
    );
    fs::write(d.join("butterfly.html"), page).unwrap();
}

/// The rows of the miss table, the ones shown and the ones folded away after the worst
/// `SHOWN_ROWS`: (cycle, cause in words).
fn miss_rows(page: &str) -> Vec<(u64, String)> {
    let rows = |id: &str| -> Vec<(u64, String)> {
        let Some(at) = page.find(&format!("id=\"{id}\"")) else {
            return Vec::new();
        };
        let table = &page[at..];
        let table = &table[..table.find("</table>").unwrap()];
        table
            .split("<tr><td>")
            .skip(1)
            .map(|r| {
                let cells: Vec<&str> = r.split("<td>").collect();
                let cycle = r[..r.find('<').unwrap()].parse().unwrap();
                let cause = cells[4].trim_end_matches("</td>").to_string();
                (cycle, cause)
            })
            .collect()
    };
    let shown = rows("miss-table");
    let folded = rows("miss-table-more");
    let limit = interpreter::html::timing::SHOWN_ROWS;
    assert!(shown.len() <= limit, "{} rows shown", shown.len());
    assert!(folded.is_empty() || shown.len() == limit);
    assert_eq!(
        page.contains("<details><summary>The other"),
        !folded.is_empty()
    );
    shown.into_iter().chain(folded).collect()
}

/// The misses of a deadline-misses.json: (cycle, cause in words), in cycle order.
fn deadline_misses(run: &Path) -> Vec<(u64, String)> {
    let d: Value =
        serde_json::from_str(&fs::read_to_string(run.join("deadline-misses.json")).unwrap())
            .unwrap();
    d["miss_list"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| {
            (
                m["cycle"].as_u64().unwrap(),
                interpolator::deadline::cause_words(m["cause"].as_str().unwrap()).to_string(),
            )
        })
        .collect()
}

#[test]
fn misses_are_listed_exactly() {
    let run = circle_run("misses");
    let mut rep = report(&run);
    rep["clock"] = "real".into();
    rep["misses"] = 5.into();
    for k in ["wake_late_ns", "compute_ns", "publish_ns"] {
        rep[k] = serde_json::json!({"p50": 20000, "p99": 90000, "max": 1500000});
    }
    let miss = |cycle: u64, cause: &str, overrun: u64| {
        serde_json::json!({"cycle": cycle, "line": 3, "cause": cause, "wake_late_ns": 1_200_000,
            "compute_ns": 5_000, "publish_ns": 9_000, "overrun_ns": overrun})
    };
    let mut preempted = miss(900, "preempted", 600_000);
    preempted["wake_late_ns"] = 20_000.into();
    preempted["compute_ns"] = 1_581_000.into();
    preempted["cpu_ns"] = 42_000.into();
    preempted["preempted_ns"] = 1_539_000.into();
    let list = serde_json::json!([
        miss(100, "late_wake", 250_000),
        miss(700, "long_compute", 40_000),
        miss(701, "downstream_lag", 1_010_000),
        preempted,
        miss(1200, "publish_stall", 1_000_000)
    ]);
    rep["miss_list"] = list.clone();
    fs::write(run.join("report.json"), rep.to_string()).unwrap();
    // deadline-misses.json as the interpolator writes it, with histograms.
    let mut d: Value =
        serde_json::from_str(&fs::read_to_string(run.join("deadline-misses.json")).unwrap())
            .unwrap();
    let fig = serde_json::json!({
        "percentiles": {"p50": 20000, "p90": 40000, "p99": 90000, "p999": 300000, "max": 1500000},
        "min_ns": 9000, "mean_ns": 25000.0,
        "histogram": [{"lo_ns": 19456, "hi_ns": 20480, "count": 1200},
                      {"lo_ns": 1441792, "hi_ns": 1507328, "count": 3}]});
    for k in ["wake_late_ns", "compute_ns", "publish_ns"] {
        d[k] = fig.clone();
    }
    d["measured"] = true.into();
    d["clock"] = "real".into();
    d["not_measured"] = Value::Null;
    d["misses"] = 5.into();
    d["miss_list"] = list;
    d["runs"] = serde_json::json!([{"start_cycle": 700, "length": 2}]);
    d["summary"] = "5 deadline misses in 1300 cycles".into();
    d["vs_floor"] = "no latency test measured on this machine".into();
    fs::write(run.join("deadline-misses.json"), d.to_string()).unwrap();

    let page = html::render(&run).unwrap();
    for id in [
        "wake-hist",
        "compute-hist",
        "publish-hist",
        "miss-plot",
        "miss-table",
        "timing-table",
        "runs-table",
        "floor-compare",
    ] {
        assert!(page.contains(&format!("id=\"{id}\"")), "no {id}");
    }
    let rows = miss_rows(&page);
    // Worst first, each with its source line and cause in words.
    let cycles: Vec<u64> = rows.iter().map(|r| r.0).collect();
    assert_eq!(cycles, [701, 1200, 900, 100, 700]);
    let mut sorted = rows.clone();
    sorted.sort();
    assert_eq!(sorted, deadline_misses(&run));
    assert_eq!(rows[0].1, "downstream not consuming");
    assert_eq!(rows[1].1, "publish stall");
    assert_eq!(rows[2].1, "preempted mid-compute");
    assert_eq!(rows[3].1, "late wake-up");
    assert_eq!(rows[4].1, "long compute");
    // The preempted miss shows how long its compute was off the CPU, and the plot's
    // legend names the cause.
    let table = &page[page.find("id=\"miss-table\"").unwrap()..];
    assert!(table.contains("<th>off the CPU (µs)</th>"));
    assert!(table.contains("<td>1581.0</td><td>1539.0</td>"));
    let plot = &page[page.find("id=\"miss-plot\"").unwrap()..];
    assert!(plot[..plot.find("</svg>").unwrap()].contains(">preempted mid-compute</text>"));
    assert!(page.contains("G3 X10 Y0 I-10 J0 F3000"));
    assert!(page.contains("period 1000 µs"));
    assert!(cell(&page, "misses").contains('5'));

    // An older run directory without deadline-misses.json: report.json's figures.
    fs::remove_file(run.join("deadline-misses.json")).unwrap();
    let page = html::render(&run).unwrap();
    assert!(page.contains("id=\"pct-plot\""));
    assert!(!page.contains("id=\"wake-hist\""));
    assert_eq!(miss_rows(&page).len(), 5);
    assert!(page.contains("<td>1581.0</td><td>1539.0</td>"));
    assert!(page.contains("no deadline-misses.json"));
}

/// A real-clock run with injected long computes: the page draws the histograms with the
/// period and lists exactly the misses of deadline-misses.json.
#[test]
fn real_run_page_has_histograms_and_exactly_the_misses() {
    let d = scratch("real");
    let prog = d.join("circle.ngc");
    fs::write(&prog, CIRCLE).unwrap();
    let run = d.join("run");
    let o = Command::new(env!("CARGO_BIN_EXE_cnc"))
        .args(["run", "--clock", "real", "--out"])
        .arg(&run)
        .arg(&prog)
        .env("CNC_INJECT_LONG_COMPUTE", "50")
        .env("CNC_LATENCY_FILE", d.join("no-latency-test.json"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let page = fs::read_to_string(run.join("report.html")).unwrap();
    let rep = report(&run);
    check_summary(&page, &rep);
    check_plots(&page);
    for id in ["wake-hist", "compute-hist", "publish-hist"] {
        let at = page.find(&format!("id=\"{id}\"")).unwrap();
        let svg = &page[at..at + page[at..].find("</svg>").unwrap()];
        for l in [
            "(µs, log scale)",
            "cycles (log scale)",
            "period 1000 µs",
            "<rect",
        ] {
            assert!(svg.contains(l), "{id}: no `{l}`");
        }
    }
    let listed = deadline_misses(&run);
    assert!(listed.len() >= 20, "the injected misses are there");
    let mut rows = miss_rows(&page);
    rows.sort();
    assert_eq!(
        rows, listed,
        "the table lists exactly the misses of deadline-misses.json"
    );
    assert!(page.contains("no latency test measured"));
    assert!(cell(&page, "misses").contains(&rep["misses"].to_string()));
}

#[test]
fn damaged_run_directories_are_named_never_a_panic() {
    let good = circle_run("damaged");
    let d = good.parent().unwrap().to_path_buf();

    // setpoints.csv cut off mid-row: the page names file and line and draws the rest.
    let cut = d.join("cut");
    copy_dir(&good, &cut);
    let text = fs::read_to_string(cut.join("setpoints.csv")).unwrap();
    let at = text.len() / 2;
    let at = at + text[at..].find(',').unwrap() + 1; // inside a row
    fs::write(cut.join("setpoints.csv"), &text[..at]).unwrap();
    let whole_rows = text[..at].matches('\n').count();
    let page = html::render(&cut).unwrap();
    assert!(page.contains("id=\"problems\""));
    assert!(
        page.contains(&format!("setpoints.csv:{}: ", whole_rows + 1)),
        "names the cut line"
    );
    assert!(
        page.contains("id=\"feed-plot\""),
        "the rows before the cut are drawn"
    );

    // A value that is not a number.
    let nan = d.join("nan");
    copy_dir(&good, &nan);
    let text = fs::read_to_string(nan.join("feedback.csv")).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let mut cells: Vec<&str> = lines[10].split(',').collect();
    cells[5] = "abc";
    lines[10] = cells.join(",");
    fs::write(nan.join("feedback.csv"), lines.join("\n")).unwrap();
    let page = html::render(&nan).unwrap();
    assert!(page.contains("feedback.csv:11: column `ferr_x_um`: `abc` is not a number"));

    // No report.json: the page says so where the summary would be.
    let norep = d.join("norep");
    copy_dir(&good, &norep);
    fs::remove_file(norep.join("report.json")).unwrap();
    let page = html::render(&norep).unwrap();
    assert!(page.contains("report.json: "));
    assert!(page.contains("No summary figures"));
    assert!(page.contains("id=\"path-plot\""));
    // The timing comes from deadline-misses.json (this run's: not measured) ...
    assert!(page.contains("id=\"timing-not-measured\""));
    // ... and without it too it is unknown.
    fs::remove_file(norep.join("deadline-misses.json")).unwrap();
    let page = html::render(&norep).unwrap();
    assert!(page.contains("Timing unknown"));

    // A report.json that is not JSON: named with line and column.
    let bad = d.join("badjson");
    copy_dir(&good, &bad);
    fs::write(bad.join("report.json"), "{\n  \"outcome\": done\n}").unwrap();
    let page = html::render(&bad).unwrap();
    assert!(page.contains("report.json:2:"), "names the line");

    // An older report without some fields: those are "not recorded", the rest shown.
    let old = d.join("old");
    copy_dir(&good, &old);
    let mut rep = report(&old);
    rep.as_object_mut().unwrap().remove("path_length_mm");
    fs::write(old.join("report.json"), rep.to_string()).unwrap();
    let page = html::render(&old).unwrap();
    assert!(cell(&page, "path_length_mm").contains("not recorded"));
    assert!(page.contains("no usable path_length_mm"));
    assert_eq!(
        cell(&page, "time_s"),
        format!("{:.3} s", rep["time_s"].as_f64().unwrap())
    );

    // Nothing usable at all, and no directory at all: errors naming the files.
    let empty = d.join("empty");
    fs::create_dir_all(&empty).unwrap();
    let err = html::render(&empty).unwrap_err();
    assert!(matches!(err, HtmlError::NothingUsable { .. }));
    let msg = err.to_string();
    for f in ["report.json", "setpoints.csv", "commands.log"] {
        assert!(msg.contains(f), "{msg}");
    }
    let err = html::render(&d.join("nope")).unwrap_err();
    assert!(err.to_string().contains("not a run directory"));

    // Every file cut at many lengths: a page or an error, never a panic.
    let fuzz = d.join("fuzz");
    for name in [
        "report.json",
        "setpoints.csv",
        "feedback.csv",
        "commands.log",
        "machine.toml",
        "program.ngc",
        "deadline-misses.json",
    ] {
        let full = fs::read(good.join(name)).unwrap();
        for k in 0..=8 {
            let _ = fs::remove_dir_all(&fuzz);
            copy_dir(&good, &fuzz);
            fs::write(fuzz.join(name), &full[..full.len() * k / 8]).unwrap();
            match html::render(&fuzz) {
                Ok(page) => {
                    assert!(page.ends_with("</html>\n"));
                    if k < 8 && name != "program.ngc" && name != "machine.toml" {
                        assert!(
                            page.contains("id=\"problems\""),
                            "{name} cut at {k}/8 not reported"
                        );
                    }
                }
                Err(e) => assert!(!e.to_string().is_empty()),
            }
        }
    }
}

/// A run directory of `n` cycles: the circle's blocks, a circle traced over and over, and
/// one following-error spike of 777 µm in the middle.
fn synthetic(dir: &Path, from: &Path, n: u64) {
    copy_dir(from, dir);
    let mut sp = String::from("cycle,t_ns,x_mm,y_mm,z_mm,line\n");
    let mut fb = String::from("cycle,t_ns,x_mm,y_mm,z_mm,ferr_x_um,ferr_y_um,ferr_z_um\n");
    use std::fmt::Write;
    for k in 0..n {
        let a = k as f64 * 0.004;
        let (x, y) = (10.0 * a.cos(), 10.0 * a.sin());
        let spike = if k == n / 2 { 777.0 } else { 3.0 * a.sin() };
        let t = k * 1_000_000;
        let _ = writeln!(sp, "{k},{t},{x},{y},0,3");
        let _ = writeln!(fb, "{k},{t},{x},{y},0,{spike},1,0");
    }
    fs::write(dir.join("setpoints.csv"), sp).unwrap();
    fs::write(dir.join("feedback.csv"), fb).unwrap();
}

#[test]
fn page_size_does_not_grow_with_run_length() {
    let good = circle_run("scale");
    let d = good.parent().unwrap().to_path_buf();
    let mut sizes = Vec::new();
    for n in [20_000, 300_000] {
        let dir = d.join(format!("n{n}"));
        synthetic(&dir, &good, n);
        let page = html::render(&dir).unwrap();
        // The one-cycle spike survives the reduction: the y axis reaches past it.
        let ferr = &page[page.find("id=\"ferr-plot\"").unwrap()..];
        let ferr = &ferr[..ferr.find("</svg>").unwrap()];
        assert!(ferr.contains(">800</text>"), "spike of 777 µm lost");
        sizes.push(page.len());
    }
    assert!(sizes[1] < 5_000_000);
    assert!(
        (sizes[1] as f64) < sizes[0] as f64 * 1.3,
        "15× the cycles made the page grow from {} to {} bytes",
        sizes[0],
        sizes[1]
    );
}

/// One hour at 1 ms (3.6 million set-points): run by hand with
/// `cargo test --release -p interpreter --test html_report -- --ignored --nocapture`.
#[test]
#[ignore]
fn one_hour_run_stays_under_5_mb() {
    let good = circle_run("hour");
    let dir = good.parent().unwrap().join("hour");
    synthetic(&dir, &good, 3_600_000);
    let t = std::time::Instant::now();
    let page = html::render(&dir).unwrap();
    println!("one-hour run: {} bytes in {:.2?}", page.len(), t.elapsed());
    assert!(page.len() < 5_000_000);
}

/// A run under cutter radius compensation (`examples/nurbs-comp.ngc`: lines and a NURBS
/// under `G42.1`) shows the path as programmed beside the tool's, named in the legend
/// and the note; a run without compensation (the circle) shows no such line.
#[test]
fn a_compensated_run_shows_the_programmed_path_beside_the_tool_s() {
    let d = scratch("comp");
    let prog = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/nurbs-comp.ngc");
    let run = d.join("run");
    run_sim(Some(&prog), &run);
    let page = html::render(&run).unwrap();
    check_summary(&page, &report(&run));
    check_plots(&page);
    assert!(
        page.contains("<g class=\"programmed\">"),
        "no programmed path"
    );
    assert!(page.contains("as programmed (before cutter compensation)"));
    assert!(page.contains("the coloured path is the tool's centre"));
    // One polyline for each programmed feed move (entry, six sides and the wave, exit).
    let group = &page[page.find("<g class=\"programmed\">").unwrap()..];
    let group = &group[..group.find("</g>").unwrap()];
    assert!(group.matches("<polyline").count() >= 6, "{group}");
    let circle = circle_run("comp-none");
    let page = html::render(&circle).unwrap();
    assert!(!page.contains("class=\"programmed\""));
}

/// A feed above the machine's `max_feed_mm_per_min` runs at that limit, and a user is
/// told: `cnc check` and `cnc run` print a note naming the first line that asks for it
/// (and how many more moves do), `report.json` keeps it, and the page's summary shows
/// it. A program within the limit gets no note.
#[test]
fn a_feed_above_the_machine_s_limit_is_a_note_with_its_line() {
    let d = scratch("feed-note");
    let prog = d.join("fast.ngc");
    // The built-in machine's max_feed_mm_per_min is 10 000.
    fs::write(
        &prog,
        "G21 G90 G94\nG1 X10 F20000\nG1 X20\nG1 X30 F500\nM2\n",
    )
    .unwrap();
    let says = "fast.ngc:2: note: feed 20000 mm/min is above the machine's max_feed_mm_per_min: this move and 1 more at that feed run at 10000 mm/min";
    let o = Command::new(env!("CARGO_BIN_EXE_cnc"))
        .arg("check")
        .arg(&prog)
        .output()
        .unwrap();
    assert!(o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains(says), "{err}");
    assert_eq!(err.matches("note:").count(), 1, "{err}");
    let run = d.join("run");
    run_sim(Some(&prog), &run);
    let notes = &report(&run)["notes"];
    assert_eq!(notes[0][0], 2, "{notes}");
    assert!(notes[0][1]
        .as_str()
        .unwrap()
        .starts_with("feed 20000 mm/min"));
    let page = fs::read_to_string(html::write(&run, None).unwrap()).unwrap();
    assert!(cell(&page, "notes").contains("line 2: feed 20000 mm/min"));
    // An inch feed at the limit (34.2 in/min is 868.68 mm/min, a hair over in floating
    // point) is at the limit: no note.
    let machine = d.join("m.toml");
    fs::write(&machine, "max_feed_mm_per_min = 868.68\n").unwrap();
    fs::write(&prog, "G20 G90 G94\nG1 X1 F34.2\nM2\n").unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_cnc"))
        .arg("check")
        .arg("--machine")
        .arg(&machine)
        .arg(&prog)
        .output()
        .unwrap();
    assert!(o.status.success());
    assert!(!String::from_utf8_lossy(&o.stderr).contains("note:"));
    // Within the limit: nothing to say.
    fs::write(&prog, "G21 G90 G94\nG1 X10 F2000\nM2\n").unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_cnc"))
        .arg("check")
        .arg(&prog)
        .output()
        .unwrap();
    assert!(!String::from_utf8_lossy(&o.stderr).contains("note:"));
}

/// `RUST_LOG=info` shows the program's `(MSG, …)` on stderr, and a pipe gets it as
/// plain text: no terminal colour codes where stderr is not a terminal.
#[test]
fn logs_to_a_pipe_are_plain_text() {
    let d = scratch("plain-log");
    let prog = d.join("msg.ngc");
    fs::write(&prog, "G21 G90\n(MSG, hello there)\nG1 X5 F1000\nM2\n").unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_cnc"))
        .args(["run", "--clock", "sim", "--out"])
        .arg(d.join("run"))
        .arg(&prog)
        .env("RUST_LOG", "info")
        .output()
        .unwrap();
    assert!(o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("msg.ngc:2: MSG hello there"), "{err}");
    assert!(!err.contains('\u{1b}'), "colour codes in a pipe: {err:?}");
}

/// Thirty misses: the worst twenty in the table, the other ten folded away under a
/// `<details>` (the page needs no script to open it), all still listed, worst first.
#[test]
fn misses_after_the_worst_twenty_are_folded_away() {
    let run = circle_run("fold");
    let list: Vec<Value> = (0..30u64)
        .map(|k| {
            serde_json::json!({"cycle": 100 + k, "line": 3, "cause": "late_wake",
                "wake_late_ns": 1_200_000, "compute_ns": 5_000, "publish_ns": 9_000,
                "overrun_ns": 10_000 * (k + 1)})
        })
        .collect();
    let mut rep = report(&run);
    rep["clock"] = "real".into();
    rep["misses"] = 30.into();
    for k in ["wake_late_ns", "compute_ns", "publish_ns"] {
        rep[k] = serde_json::json!({"p50": 20000, "p99": 90000, "max": 1500000});
    }
    rep["miss_list"] = list.clone().into();
    fs::write(run.join("report.json"), rep.to_string()).unwrap();
    let mut d: Value =
        serde_json::from_str(&fs::read_to_string(run.join("deadline-misses.json")).unwrap())
            .unwrap();
    d["measured"] = true.into();
    d["clock"] = "real".into();
    d["misses"] = 30.into();
    d["miss_list"] = list.into();
    fs::write(run.join("deadline-misses.json"), d.to_string()).unwrap();
    let page = html::render(&run).unwrap();
    let rows = miss_rows(&page);
    let cycles: Vec<u64> = rows.iter().map(|r| r.0).collect();
    assert_eq!(cycles, (100..130).rev().collect::<Vec<u64>>());
    assert!(page.contains("<details><summary>The other 10 misses listed</summary>"));
}

/// The feed plot's scale is the feed moves' where rapids are more than twice as fast:
/// at F300 with 10 000 mm/min rapids the feed is not a flat line at the bottom. On a
/// STEP-NC part, whose surface passes share their source line with the rapids between
/// them, the feed limit drawn is the passes' (it was the rapid rate over the whole run,
/// and so was the scale).
#[test]
fn the_feed_moves_set_the_feed_plot_s_scale() {
    let d = scratch("feed-scale");
    let prog = d.join("slow.ngc");
    fs::write(
        &prog,
        "G21 G90 G94\nG0 X50 Y0\nG1 X50 Y20 F300\nG0 X0 Y0\nM2\n",
    )
    .unwrap();
    let run = d.join("run");
    run_sim(Some(&prog), &run);
    let page = fs::read_to_string(html::write(&run, None).unwrap()).unwrap();
    assert!(
        page.contains("The scale is the feed moves': rapids, up to 10000 mm/min, run off the top."),
        "no note of the scale"
    );
    let part = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/seed-surface.stp");
    let run = d.join("step");
    run_sim(Some(&part), &run);
    let page = fs::read_to_string(html::write(&run, None).unwrap()).unwrap();
    assert!(page.contains("rapids, up to 10000 mm/min, run off the top"));
}

/// The SVG of the chart `id` in `page`.
fn chart<'a>(page: &'a str, id: &str) -> &'a str {
    let at = page
        .find(&format!("id=\"{id}\""))
        .unwrap_or_else(|| panic!("no {id}"));
    &page[at..at + page[at..].find("</svg>").unwrap()]
}

/// The drawn length (px) of the polylines of `class` in `svg`.
fn drawn_px(svg: &str, class: &str) -> f64 {
    let tag = format!("class=\"{class}\" points=\"");
    let mut total = 0.0;
    for part in svg.split(&tag).skip(1) {
        let pts: Vec<(f64, f64)> = part[..part.find('"').unwrap()]
            .split(' ')
            .map(|p| {
                let (x, y) = p.split_once(',').unwrap();
                (x.parse().unwrap(), y.parse().unwrap())
            })
            .collect();
        total += pts
            .windows(2)
            .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1))
            .sum::<f64>();
    }
    total
}

/// A run stopped by a fault draws the rest of its path, which never ran, apart from
/// what was cut, split where the last set-point lies; a run that completes has none.
#[test]
fn a_faulted_run_draws_the_path_that_never_ran_apart() {
    let d = scratch("never-ran");
    let machine = String::from_utf8(
        Command::new(env!("CARGO_BIN_EXE_cnc"))
            .arg("machine")
            .output()
            .unwrap()
            .stdout,
    )
    .unwrap();
    // A following-error limit of 5 µm: the polygon at F3000 trips it a quarter of the
    // way round.
    let tight: String = machine
        .lines()
        .map(|l| {
            if l.starts_with("max_following_error_mm") {
                "max_following_error_mm = 0.005\n".to_string()
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    let mfile = d.join("tight.toml");
    fs::write(&mfile, tight).unwrap();
    let part = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/cam-polygon.ngc");
    let run = d.join("run");
    let o = Command::new(env!("CARGO_BIN_EXE_cnc"))
        .args(["run", "--clock", "sim", "--machine"])
        .arg(&mfile)
        .arg("--out")
        .arg(&run)
        .arg(&part)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let rep = report(&run);
    assert_eq!(rep["outcome"], "fault");
    // A quarter of the way round, the polygon has no roundness (it had 67.65 µm, the
    // fit of a quarter arc).
    assert!(rep["roundness"].is_null(), "{}", rep["roundness"]);
    let page = fs::read_to_string(html::write(&run, None).unwrap()).unwrap();
    assert!(page.contains("the run stopped before it went round the circle"));
    let plot = chart(&page, "path-plot");
    assert!(plot.contains("never ran (after the stop)"));
    // The share of the path drawn as cut is the share that ran: the run's path length
    // over the polygon's (60 chords of a 100 mm circle), within 1 %.
    let whole = 60.0 * 100.0 * (3.0f64).to_radians().sin();
    let ran = rep["path_length_mm"].as_f64().unwrap() / whole;
    let (cut, not_run) = (drawn_px(plot, "feed"), drawn_px(plot, "notrun"));
    assert!(not_run > 0.0, "nothing drawn as never ran");
    let drawn = cut / (cut + not_run);
    assert!(
        (drawn - ran).abs() < 0.01,
        "drawn as cut {drawn:.4} of the path, ran {ran:.4}"
    );
    assert!(page.contains("the light grey rest of the path never ran"));

    let done = circle_run("never-ran-done");
    let page = fs::read_to_string(html::write(&done, None).unwrap()).unwrap();
    assert!(!page.contains("class=\"notrun\""));
}

/// The path coloured by contour error: a second plot behind a switch that needs no
/// script, its colour scale reaching the largest error of the summary, and drawn once
/// per area of the path, however often the path goes over it.
#[test]
fn the_path_is_coloured_by_contour_error_behind_a_switch() {
    let run = circle_run("by-error");
    let page = fs::read_to_string(html::write(&run, None).unwrap()).unwrap();
    assert!(page.contains("<input type=\"radio\" name=\"path-colour\" id=\"path-by-error\">"));
    assert!(page.contains("#path-by-error:checked~.by-error{display:flex}"));
    let plot = chart(&page, "path-error-plot");
    assert!(drawn_px(plot, "feed") > 100.0, "no error path drawn");
    // The scale's top label is at least the largest contour error.
    let max = report(&run)["max_contour_error_um"].as_f64().unwrap();
    let bar = &page[page
        .find("aria-label=\"contour error (µm) colour scale\"")
        .unwrap()..];
    let bar = &bar[..bar.find("</svg>").unwrap()];
    let top: f64 = bar
        .rsplit("class=\"lg\">")
        .next()
        .unwrap()
        .split('<')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    // (`nice_ceil` steps 1, 2, 5, 10: at most 2.5 times the largest.)
    assert!(
        top >= max && top <= 2.5 * max.max(1e-3),
        "scale to {top}, max {max}"
    );
    // Each area of the path is drawn once: the circle run 19 times over (the synthetic
    // long run) draws less than twice the length of once (19 times without the rule;
    // a loop a fraction of a pixel off the others still finds a few cells new).
    let d = run.parent().unwrap().join("long");
    synthetic(&d, &run, 30_000);
    let long = html::render(&d).unwrap();
    let once = drawn_px(chart(&page, "path-error-plot"), "feed");
    let many = drawn_px(chart(&long, "path-error-plot"), "feed");
    assert!(
        many < 2.0 * once && many > 0.8 * once,
        "{many} px against {once} px"
    );
    // Fast over a small part, consecutive cycles land pixels apart: the path is still
    // drawn whole (it fell apart into single points, none drawn): as long as the path
    // plot's, within a fifth.
    let d = run.parent().unwrap().join("small-fast");
    fs::create_dir_all(&d).unwrap();
    let prog = d.join("small.ngc");
    fs::write(&prog, "G21 G17 G90\nG0 X3 Y0\nG3 X3 Y0 I-3 J0 F6000\nM2\n").unwrap();
    let fast = d.join("run");
    run_sim(Some(&prog), &fast);
    let page = fs::read_to_string(html::write(&fast, None).unwrap()).unwrap();
    let by_error = drawn_px(chart(&page, "path-error-plot"), "feed");
    let by_feed = drawn_px(chart(&page, "path-plot"), "feed");
    assert!(
        (by_error - by_feed).abs() < 0.2 * by_feed,
        "by error {by_error} px, by feed {by_feed} px"
    );
}

/// A path that moves in three axes, and a STEP-NC part, get the isometric view and the
/// three planes; the part its surface as a wireframe, the tool's tip on it, the peak
/// feed named as the tool centre's, and a scallop map. A flat path gets none of them.
#[test]
fn paths_in_three_axes_and_surface_parts_get_a_3d_view() {
    let d = scratch("view3d");
    let prog = d.join("helix.ngc");
    fs::write(
        &prog,
        "G21 G17 G90\nG0 X10 Y0 Z5\nG1 Z0 F600\nG3 X10 Y0 Z-3 I-10 J0 F1200\nG0 Z5\nM2\n",
    )
    .unwrap();
    let run = d.join("helix");
    run_sim(Some(&prog), &run);
    let page = fs::read_to_string(html::write(&run, None).unwrap()).unwrap();
    for id in ["iso-plot", "plane-xy", "plane-xz", "plane-yz"] {
        assert!(drawn_px(chart(&page, id), "feed") > 50.0, "{id}: no path");
    }
    assert!(!page.contains("class=\"wire\""));
    assert!(cell(&page, "peak_feed_mm_per_min").ends_with(" mm/min"));

    let part = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/torus-patch.stp");
    let run = d.join("torus");
    run_sim(Some(&part), &run);
    let page = fs::read_to_string(html::write(&run, None).unwrap()).unwrap();
    let iso = chart(&page, "iso-plot");
    assert!(iso.contains("<g class=\"wire\">"), "no surface wireframe");
    assert!(page.contains("The path is the tool's tip"));
    // The passes lie on the surface: in the isometric view, the cut's drawn points lie
    // within the wireframe's box, widened by the tip's distance from the surface (at
    // most √2 times the 3 mm ball's radius, 4.2 mm, which the projection can stretch
    // by up to 1.22: under 60 px at this view's 9 px/mm). Without the tool length
    // taken off they were 80 mm (some 700 px) above it.
    let points_of = |svg: &str, tag: &str| -> Vec<(f64, f64)> {
        let mut v = Vec::new();
        for part in svg.split(tag).skip(1) {
            for p in part[..part.find('"').unwrap()].split(' ') {
                let (x, y) = p.split_once(',').unwrap();
                v.push((x.parse().unwrap(), y.parse().unwrap()));
            }
        }
        v
    };
    let wire = &iso[iso.find("<g class=\"wire\">").unwrap()..];
    let wire = &wire[..wire.find("</g>").unwrap()];
    let boxed = |v: &[(f64, f64)]| {
        v.iter().fold(
            (
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
            ),
            |b, p| (b.0.min(p.0), b.1.max(p.0), b.2.min(p.1), b.3.max(p.1)),
        )
    };
    let w = boxed(&points_of(wire, "points=\""));
    let c = boxed(&points_of(iso, "class=\"feed\" points=\""));
    assert!(
        c.0 >= w.0 - 60.0 && c.1 <= w.1 + 60.0 && c.2 >= w.2 - 60.0 && c.3 <= w.3 + 60.0,
        "cut in {c:?} px, surface in {w:?} px"
    );
    assert!(cell(&page, "peak_feed_mm_per_min").contains("the tool's reference point"));
    // The scallop map: cells over the part, the summary's largest scallop marked.
    let map = chart(&page, "scallop-map");
    assert!(map.matches("<rect ").count() > 100, "no scallop cells");
    let measured = report(&run)["measured_max_scallop_mm"].as_f64().unwrap();
    assert!(map.contains(&format!("max {:.2} µm", measured * 1e3)));

    let flat = circle_run("view3d-flat");
    let page = fs::read_to_string(html::write(&flat, None).unwrap()).unwrap();
    assert!(!page.contains("id=\"view3d\""));
    assert!(!page.contains("id=\"scallop\""));
}

/// A circle run both ways overlays the second direction's measured trace on the polar
/// plot, about the first's centre and radius, as on a ballbar report; the ramps from
/// and to rest at each circle's ends are left out of the plot (the figures keep them,
/// beside a roundness at steady speed).
#[test]
fn a_circle_run_both_ways_overlays_on_the_polar_plot_without_its_ramps() {
    let d = scratch("both-ways");
    let prog = d.join("both.ngc");
    fs::write(
        &prog,
        "G21 G17 G90\nG0 X10 Y0\nG3 X10 Y0 I-10 J0 F3000\nG0 X12 Y0\nG0 X10 Y0\nG2 X10 Y0 I-10 J0 F3000\nM2\n",
    )
    .unwrap();
    let run = d.join("run");
    run_sim(Some(&prog), &run);
    let c = interpreter::contour::analyse_dir(&run).unwrap();
    let r = c.roundness.as_ref().unwrap();
    assert!(r.ccw, "the first circle is G3");
    let rev = r
        .reverse
        .as_ref()
        .expect("the G2 circle as the reverse run");
    assert_eq!(rev.lines, (6, 6));
    // Both start and stop at rest: each leaves out its ramps, about 3000 mm/min over
    // 2000 mm/s² with the jerk, some 30 to 100 cycles each end.
    for (head, tail) in [r.ramps_left_out, rev.ramps_left_out] {
        assert!(
            (20..200).contains(&head) && (20..200).contains(&tail),
            "{head}, {tail}"
        );
    }
    // The figures count every cycle on the circle (62.83 mm at 50 mm/s, 1257 cycles
    // and its ramps); the roundness at steady speed, without the ramps, is at most it.
    let on_circle = r.measured.len();
    assert!((1250..1500).contains(&on_circle), "{on_circle} cycles");
    assert!(r.steady_roundness_um() <= r.roundness_um);
    // The two traces lie about one centre: the reverse run's radius is the first's
    // within a micrometre (the same servo, the same circle).
    assert!(rev.radius_offset_um.abs() < 1.0, "{rev:?}");
    let page = fs::read_to_string(html::write(&run, None).unwrap()).unwrap();
    let polar = chart(&page, "polar-plot");
    assert!(polar.contains("measured, counter-clockwise"));
    assert!(polar.contains("measured, clockwise"));
    assert_eq!(
        polar.matches("<polyline").count(),
        3,
        "commanded and both measured"
    );
    assert!(page.contains("id=\"reverse-run\""));
    assert!(page.contains("as a ballbar test leaves out its feed-in and feed-out arcs"));
    assert!(page.contains("id=\"steady-roundness\""));
    // Without a rapid between, two turns one way and one back net one turn, but are no
    // circle run one way (they were taken for one): the two turns one way are the run
    // measured, the one back its reverse.
    let prog = d.join("no-rapid.ngc");
    fs::write(
        &prog,
        "G21 G17 G90\nG0 X10 Y0\nG2 X10 Y0 I-10 J0 F3000\nG2 X10 Y0 I-10 J0\nG3 X10 Y0 I-10 J0\nM2\n",
    )
    .unwrap();
    let run = d.join("no-rapid");
    run_sim(Some(&prog), &run);
    let c = interpreter::contour::analyse_dir(&run).unwrap();
    let r = c.roundness.as_ref().unwrap();
    assert_eq!(r.lines, (3, 4), "{:?}", r.lines);
    assert!(!r.ccw);
    assert_eq!(r.reverse.as_ref().map(|v| v.lines), Some((5, 5)));
    // One circle alone has no overlay.
    let one = circle_run("one-way");
    let c = interpreter::contour::analyse_dir(&one).unwrap();
    assert!(c.roundness.unwrap().reverse.is_none());
}

/// A STEP-NC workingstep whose feed is above the machine's is a note at its line, from
/// `cnc check` and into the run's figures, as a G-code move's is (it was clamped
/// without a word).
#[test]
fn a_step_part_s_feed_above_the_machine_s_limit_is_a_note_at_its_workingstep() {
    let d = scratch("step-feed-note");
    let text = fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/torus-patch.stp"),
    )
    .unwrap()
    .replace("MILLING_TECHNOLOGY(30.0,", "MILLING_TECHNOLOGY(300.0,");
    let part = d.join("fast.stp");
    fs::write(&part, &text).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_cnc"))
        .arg("check")
        .arg(&part)
        .output()
        .unwrap();
    assert!(out.status.success());
    let want = "fast.stp:40: note: feed 18000 mm/min is above the machine's max_feed_mm_per_min: the workingstep runs at 10000 mm/min";
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains(want), "{stderr}");
    let m = shared::Machine::default();
    let c = interpreter::process::compile_source(
        "fast.stp",
        &text,
        &interpreter::program::Options::default(),
        &m,
        1_000_000,
    )
    .unwrap();
    assert_eq!(c.notes.len(), 1);
    assert_eq!(c.notes[0].0, 40);
}

/// The 3D views cost the page little however many blocks the path has: runs of one
/// style are one polyline across blocks (a circle of 3000 chords at a steady feed drew
/// a polyline a chord in each of the four views, about 1 MB).
#[test]
fn the_3d_views_of_a_path_of_many_blocks_stay_small() {
    let d = scratch("view3d-many");
    let mut prog = String::from("G21 G17 G90 G64\nG0 X20 Y0 Z1\nG1 Z-1 F600\nG1 F3000\n");
    for k in 1..=3000 {
        let a = k as f64 / 3000.0 * std::f64::consts::TAU;
        prog.push_str(&format!("X{:.4} Y{:.4}\n", 20.0 * a.cos(), 20.0 * a.sin()));
    }
    prog.push_str("G0 Z1\nM2\n");
    let file = d.join("chords.ngc");
    fs::write(&file, prog).unwrap();
    let run = d.join("run");
    run_sim(Some(&file), &run);
    let page = fs::read_to_string(html::write(&run, None).unwrap()).unwrap();
    let at = page.find("<section id=\"view3d\">").expect("a 3D view");
    let section = &page[at..at + page[at..].find("</section>").unwrap()];
    assert!(
        section.len() < 200_000,
        "the 3D views take {} bytes for 3000 blocks",
        section.len()
    );
    assert!(drawn_px(chart(&page, "iso-plot"), "feed") > 100.0);
}
