//! The report page in a real browser: headless Chromium (Debian's `chromium` package; `.ci/run`
//! installs it when missing) loads the rendered page of the demo run and of a real-clock run
//! with deadline misses, must log nothing to its console (the page has no script, so any
//! console message, such as a resource that failed to load, is a fault), and leaves PNG
//! screenshots under the target directory (`target/report-demo.png`,
//! `target/report-timing.png`) for a person to look at.
//!
//! Chromium writes the page's console messages to stderr with `--enable-logging=stderr`,
//! one `…:CONSOLE:…] "message", source: URL (line)` line each, whatever their level; the
//! test first checks that it sees them, on a probe page that logs an error on purpose.
//!
//! Without Chromium the test is skipped with a printed reason, unless `CI` is set: then it
//! fails, since CI is expected to have installed it.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// `chromium` (or `chromium-browser`) on the PATH.
fn find_chromium() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    for dir in std::env::split_paths(&path) {
        for name in ["chromium", "chromium-browser"] {
            let p = dir.join(name);
            if p.is_file() {
                return Some(p);
            }
        }
    }
    None
}

/// Chromium, or `None` (with the reason printed) when the test is to be skipped.
fn chromium_or_skip() -> Option<PathBuf> {
    match find_chromium() {
        Some(p) => Some(p),
        None if std::env::var_os("CI").is_some() => panic!(
            "chromium is not installed, and CI is set: .ci/run installs it with `apt-get install -y chromium`"
        ),
        None => {
            println!(
                "skipped: no `chromium` on the PATH (install Debian's package: apt-get install -y chromium); under CI this test fails instead"
            );
            None
        }
    }
}

fn target_dir() -> PathBuf {
    // CARGO_TARGET_TMPDIR is <target>/tmp.
    Path::new(env!("CARGO_TARGET_TMPDIR"))
        .parent()
        .map_or_else(|| PathBuf::from("target"), Path::to_path_buf)
}

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("chromium-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// What Chromium did with a page.
struct Load {
    /// The console lines about the page.
    console: Vec<String>,
    stderr: String,
}

/// Runs headless Chromium with `args` on `page` (its own profile directory, so parallel
/// runs do not share one), killing it after two minutes.
fn chromium(exe: &Path, page: &Path, args: &[String], profile: &Path) -> (Vec<u8>, Load) {
    let url = format!("file://{}", page.display());
    let mut child = Command::new(exe)
        .args([
            "--headless",
            "--disable-gpu",
            "--no-sandbox",
            "--no-first-run",
            "--enable-logging=stderr",
            "--v=0",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(args)
        .arg(&url)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("starting chromium");
    // Read both pipes on threads so neither fills up.
    let mut out = child.stdout.take().unwrap();
    let mut err = child.stderr.take().unwrap();
    let t_out = std::thread::spawn(move || {
        let mut v = Vec::new();
        let _ = std::io::Read::read_to_end(&mut out, &mut v);
        v
    });
    let t_err = std::thread::spawn(move || {
        let mut v = Vec::new();
        let _ = std::io::Read::read_to_end(&mut err, &mut v);
        v
    });
    let start = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if start.elapsed() > Duration::from_secs(120) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("chromium did not finish with {url} in 120 s");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let stdout = t_out.join().unwrap();
    let stderr = String::from_utf8_lossy(&t_err.join().unwrap()).to_string();
    let console = stderr
        .lines()
        .filter(|l| l.contains(":CONSOLE") && l.contains(&url))
        .map(str::to_owned)
        .collect();
    (stdout, Load { console, stderr })
}

/// Loads `page`, checks the console stays silent and the DOM is the report, and saves a
/// screenshot to `png`.
fn check_page(exe: &Path, page: &Path, png: &Path, work: &Path) {
    let _ = std::fs::remove_file(png);
    let (_, load) = chromium(
        exe,
        page,
        &[
            format!("--screenshot={}", png.display()),
            "--window-size=1280,4000".into(),
            "--hide-scrollbars".into(),
        ],
        &work.join("profile-shot"),
    );
    assert!(
        load.console.is_empty(),
        "{}: console messages:\n{}",
        page.display(),
        load.console.join("\n")
    );
    let img = std::fs::read(png).unwrap_or_else(|e| {
        panic!(
            "no screenshot {}: {e}\nchromium said:\n{}",
            png.display(),
            load.stderr
        )
    });
    assert_eq!(&img[..8], b"\x89PNG\r\n\x1a\n", "a PNG");
    let width = u32::from_be_bytes(img[16..20].try_into().unwrap());
    let height = u32::from_be_bytes(img[20..24].try_into().unwrap());
    assert_eq!((width, height), (1280, 4000));
    assert!(img.len() > 50_000, "a page with plots, not a blank one");
    // The DOM Chromium built is the report, not an error page.
    let (dom, load) = chromium(exe, page, &["--dump-dom".into()], &work.join("profile-dom"));
    let dom = String::from_utf8_lossy(&dom);
    assert!(load.console.is_empty(), "{}", load.console.join("\n"));
    for want in [
        "<h1>Run report: ",
        "id=\"summary\"",
        "id=\"path-plot\"",
        "id=\"timing\"",
    ] {
        assert!(dom.contains(want), "the rendered DOM has no {want}");
    }
    println!("{}: rendered, screenshot {}", page.display(), png.display());
}

fn cnc_run(out: &Path, extra: &[&str], env: &[(&str, &std::ffi::OsStr)]) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_cnc"));
    cmd.arg("run").args(extra).arg("--out").arg(out);
    for (k, v) in env {
        cmd.env(k, v);
    }
    let o = cmd.output().unwrap();
    assert!(
        o.status.success(),
        "cnc run failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn report_pages_render_in_headless_chromium_without_console_errors() {
    let Some(exe) = chromium_or_skip() else {
        return;
    };
    let work = scratch("pages");

    // The check sees console messages at all: a probe page that logs an error.
    let probe = work.join("probe.html");
    std::fs::write(
        &probe,
        "<!DOCTYPE html><html><body><p>probe</p><script>console.error('probe-error')</script></body></html>",
    )
    .unwrap();
    let (_, load) = chromium(
        &exe,
        &probe,
        &["--dump-dom".into()],
        &work.join("profile-probe"),
    );
    assert!(
        load.console.iter().any(|l| l.contains("probe-error")),
        "chromium's console lines were not seen; stderr:\n{}",
        load.stderr
    );

    // The demo (simulated clock, as the README's picture).
    let demo = work.join("demo");
    cnc_run(&demo, &["--clock", "sim"], &[]);
    check_page(
        &exe,
        &demo.join("report.html"),
        &target_dir().join("report-demo.png"),
        &work,
    );

    // A real-clock run with deadline misses: histograms, miss plot and table.
    let prog = work.join("circle.ngc");
    std::fs::write(
        &prog,
        "G21 G17 G90\nG0 X10 Y0\nG3 X10 Y0 I-10 J0 F3000\nM2\n",
    )
    .unwrap();
    let real = work.join("real");
    let no_floor = work.join("no-latency-test.json");
    cnc_run(
        &real,
        &[prog.to_str().unwrap()],
        &[
            ("CNC_LATENCY_FILE", no_floor.as_os_str()),
            ("CNC_INJECT_LONG_COMPUTE", "100".as_ref()),
        ],
    );
    let page = real.join("report.html");
    assert!(std::fs::read_to_string(&page)
        .unwrap()
        .contains("id=\"wake-hist\""));
    check_page(&exe, &page, &target_dir().join("report-timing.png"), &work);
}
