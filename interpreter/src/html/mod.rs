//! `report.html`: one self-contained page of plots made from a run directory.
//!
//! The page is for a machinist or controls engineer who wants to see a run at a glance:
//! where the tool went and how fast ([`path`]), where it slowed down and how hard it
//! accelerated ([`series`]), how far the axes lagged ([`series`]), how round a circle came
//! out ([`polar`]) and which periods came late ([`timing`]). [`data`] loads and checks the
//! run directory, [`measure`] measures the contour error and roundness, [`svg`] holds the
//! chart primitives and [`page`] assembles the HTML.
//!
//! Choices, and why:
//! * **SVG written by hand, no plotting crate.** Every chart here is a handful of
//!   polylines, ticks and labels; writing them directly keeps the page small (coordinates
//!   at 0.1 px), lets each path block carry an SVG `<title>` tooltip with its source line,
//!   and adds no dependency to the interpreter crate. The page needs no script and no
//!   network: inline SVG and one `<style>` block.
//! * **Reduction per pixel column keeping minimum and maximum** ([`svg::Reducer`]): a
//!   time series becomes at most two points per column, in the order they occurred, so a
//!   one-cycle spike still reaches its true height. The path plot drops points closer than
//!   a fraction of a pixel and raises that tolerance with the path's drawn length, so the
//!   page stays well under 5 MB whatever the run length.
//! * **Bad input never panics.** A missing or damaged file is a *problem* (`file:line:
//!   message`) listed at the top of the page, and the plots that need it say so in place;
//!   what is usable is still drawn. Only a run directory with nothing usable at all (no
//!   `report.json`, no `setpoints.csv`, no `commands.log`) is an [`HtmlError`].
//! * **Memory bounded in the run's length** (issue #25): the traces (a one-hour run's are
//!   hundreds of MB) are read once, each into an unlinked temporary file
//!   ([`crate::spill`]), and each plot reads back what it needs a row at a time; the
//!   contour analysis ([`measure`]) is `report.json`'s, a batch of rows at a time, its
//!   contour error per row to a temporary file too. What stays in memory is the command
//!   blocks, each plot's reduction, and for a surface part the measured positions its
//!   scallop map indexes.
//! * **Only measured data is drawn.** The run directory holds timing percentiles and the
//!   list of misses, not per-cycle timing, so the timing section shows exactly those and
//!   says so instead of drawing a histogram it cannot know.

pub mod data;
pub mod measure;
pub mod page;
pub mod path;
pub mod polar;
pub mod scallop;
pub mod series;
pub mod svg;
pub mod timing;
pub mod view3d;

use std::fmt;
use std::path::{Path, PathBuf};

/// Why no page could be made.
#[derive(Debug)]
pub enum HtmlError {
    /// The run directory does not exist or is not a directory.
    NotADirectory { path: PathBuf },
    /// None of `report.json`, `setpoints.csv` and `commands.log` could be read; each
    /// problem is `file[:line]: message`.
    NothingUsable { dir: PathBuf, problems: Vec<String> },
    /// The page could not be written.
    Write { path: PathBuf, err: std::io::Error },
}

impl fmt::Display for HtmlError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            HtmlError::NotADirectory { path } => {
                write!(f, "{}: not a run directory", path.display())
            }
            HtmlError::NothingUsable { dir, problems } => {
                write!(
                    f,
                    "{}: nothing to draw ({})",
                    dir.display(),
                    problems.join("; ")
                )
            }
            HtmlError::Write { path, err } => write!(f, "{}: cannot write: {err}", path.display()),
        }
    }
}

impl std::error::Error for HtmlError {}

/// The HTML page for the run directory `run_dir`.
pub fn render(run_dir: &Path) -> Result<String, HtmlError> {
    if !run_dir.is_dir() {
        return Err(HtmlError::NotADirectory {
            path: run_dir.to_path_buf(),
        });
    }
    let run = data::Run::load(run_dir);
    if run.report.is_none() && run.setpoints.is_none() && run.blocks.is_empty() {
        return Err(HtmlError::NothingUsable {
            dir: run_dir.to_path_buf(),
            problems: run.problems.clone(),
        });
    }
    Ok(page::page(&run))
}

/// Renders the page and writes it to `out` (default `run_dir/report.html`); returns the
/// path written.
pub fn write(run_dir: &Path, out: Option<&Path>) -> Result<PathBuf, HtmlError> {
    let html = render(run_dir)?;
    let path = out.map_or_else(|| run_dir.join("report.html"), Path::to_path_buf);
    std::fs::write(&path, html).map_err(|err| HtmlError::Write {
        path: path.clone(),
        err,
    })?;
    Ok(path)
}
