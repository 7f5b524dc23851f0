//! The `cnc` command line.

use crate::launch;
use crate::process::{self, Source};
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "cnc",
    version,
    about = "A NURBS CNC motion stack: interpreter -> interpolator -> servo-sim over shared memory",
    long_about = "A NURBS CNC motion stack in three processes joined by iceoryx2 shared memory:\n\
the interpreter reads and plans an NC program, the interpolator steps along the exact\n\
curves every period and publishes set-points, the servo-sim plays the drives and answers\n\
with feedback. `cnc run` starts all three and leaves a run directory with the report,\n\
the set-point and feedback traces and the command log.\n\n\
Logging: RUST_LOG=info (or debug) for more detail on stderr."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    /// Run a program (or the built-in demo) through the three-process stack.
    Run(launch::RunArgs),
    /// Check a program without running it: exit 0 if fine, else one `FILE:LINE:COL: message`
    /// line per problem on stderr and exit 1. A STEP-NC file (`.stp`, `.step`, `.p21` or an
    /// `ISO-10303-21;` header) is read as ISO 14649 free-form workingsteps and planned.
    Check {
        /// The NC program (RS274/NGC with LinuxCNC splines and NURBS, or Fanuc G06.2), or a
        /// STEP-NC part (ISO 10303-21 with ISO 14649 free-form workingsteps).
        program: PathBuf,
        /// Machine file (TOML) whose limits apply.
        #[arg(long)]
        machine: Option<PathBuf>,
        /// Also print the machining time: the program stepped cycle by cycle through the
        /// interpolator's engine, exactly as a run would (same as `time_s` of a run).
        #[arg(long)]
        estimate: bool,
        /// With --estimate: print the estimate as JSON, with the time per source line.
        #[arg(long, requires = "estimate")]
        json: bool,
        /// Interpolation period in µs the estimate assumes.
        #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(100..=10_000))]
        period_us: u64,
        /// Read the program as `linuxcnc` or `fanuc` instead of detecting the dialect.
        #[arg(long)]
        dialect: Option<crate::program::Dialect>,
        /// A directory where `o<name> call` looks for `name.ngc` after the program's own
        /// directory (LinuxCNC's SUBROUTINE_PATH); may be given several times.
        #[arg(long, value_name = "DIR")]
        subroutine_path: Vec<PathBuf>,
        /// The tool table `G41`/`G42` take the cutter's radius from (LinuxCNC's `.tbl`
        /// format: `T1 P1 D6.0 ;comment`, diameters in mm). `G41.1`/`G42.1 D…` need none.
        #[arg(long, value_name = "FILE")]
        tool_table: Option<PathBuf>,
        /// Allow what the dialect's own control refuses (see `cnc run --help`).
        #[arg(long = "dialect-extension", value_name = "NAME")]
        extensions: Vec<crate::program::dialect::Extension>,
    },
    /// Replay a command log through a fresh stack, without the NC program. Under the
    /// lock-step servo the new setpoints.csv and feedback.csv equal the original run's,
    /// byte for byte.
    Replay(crate::replay::ReplayArgs),
    /// Turn a run directory into one self-contained HTML page of plots (report.html).
    Report {
        /// The run directory.
        run_dir: PathBuf,
        /// Where to write the page [default: RUN_DIR/report.html].
        #[arg(long)]
        out: Option<PathBuf>,
        /// Open the page in the desktop's browser (says where the file is when there is none).
        #[arg(long)]
        open: bool,
    },
    /// Inspect command logs.
    #[command(subcommand)]
    Log(LogCommand),
    /// Print the built-in machine file (TOML), a starting point for your own, or make
    /// one from a LinuxCNC INI file.
    Machine {
        /// Read the limits of a LinuxCNC configuration: `[TRAJ]`, `[AXIS_X/Y/Z]` and
        /// `[JOINT_n]` velocities, accelerations and soft limits, `FERROR` and
        /// `[EMCMOT]SERVO_PERIOD`, in `[TRAJ]LINEAR_UNITS`. Each key of the machine file
        /// names the INI line it came from; each INI key with no counterpart is a
        /// warning on stderr.
        #[arg(long, value_name = "INI")]
        from_ini: Option<PathBuf>,
        /// Write the machine file here instead of to stdout.
        #[arg(long, value_name = "FILE")]
        out: Option<PathBuf>,
    },
    /// Write NURBS part programs from geometry (CAM).
    #[command(subcommand)]
    Cam(CamCommand),
    /// Measure this machine's wake-up jitter with the interpolator's own sleep and
    /// scheduling but no work (like LinuxCNC's latency-test); runs compare their lateness
    /// with the result (runs/latency-test.json).
    LatencyTest(interpolator::cli::LatencyArgs),
    /// Internal: run one process of the stack (started by `cnc run`).
    #[command(hide = true, subcommand)]
    Role(Role),
}

#[derive(Subcommand)]
pub enum CamCommand {
    /// The curves of a CAD STEP file (AP203/AP214/AP242 geometry: B-splines, rational
    /// or not, circles, ellipses, trimmed and composite curves, polylines), each cut as
    /// the exact NURBS it is: `G5.2` where its knots are clamped uniform, `G6.2` with its
    /// knots otherwise, or Fanuc's `G06.2`; polylines and trimmed lines as `G1`. The
    /// curves must lie in one plane parallel to XY (or give --project); they are cut at
    /// --depth, in the order of the file's curve sets, then by instance number. Writes
    /// the program to --out or standard output, and what was written to standard error.
    Curves {
        /// The STEP file (ISO 10303-21).
        step: PathBuf,
        /// Feed, mm/min.
        #[arg(long, default_value_t = 1000.0)]
        feed: f64,
        /// Z of the cut, mm (the tool comes down from 5 mm above it).
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        depth: f64,
        /// Cut curves out of the XY plane as their projection onto it.
        #[arg(long)]
        project: bool,
        /// The program's dialect: `linuxcnc` (G5.2 and G6.2) or `fanuc` (G06.2).
        #[arg(long, default_value = "linuxcnc")]
        dialect: crate::program::Dialect,
        /// Where to write the program [default: standard output].
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// An ellipse as an exact NURBS (a rational quadratic: no fitting error), or its offset
    /// (the path of a cutter of radius D outside it, or inside it with a negative D)
    /// fitted with the fewest cubic control points that keep within --tolerance of the
    /// true offset. Writes the program (LinuxCNC `G6.2`/`G5.2`, or Fanuc `G06.2`) to
    /// --out or standard output, and what was fitted to standard error.
    Ellipse {
        /// Semi-axis along X, mm.
        #[arg(long)]
        a: f64,
        /// Semi-axis along Y, mm.
        #[arg(long)]
        b: f64,
        /// Centre, mm.
        #[arg(long, value_name = "X,Y", value_parser = parse_xy, default_value = "0,0")]
        centre: [f64; 2],
        /// The offset, mm: outward if positive, inward if negative.
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        offset: f64,
        /// Most distance of the fitted offset from the true one, mm.
        #[arg(long, default_value_t = 1e-4)]
        tolerance: f64,
        /// Feed, mm/min.
        #[arg(long, default_value_t = 1000.0)]
        feed: f64,
        /// Z of the cut, mm (the tool comes down from 5 mm above it).
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        depth: f64,
        /// The program's dialect: `linuxcnc` (G6.2 and G5.2) or `fanuc` (G06.2).
        #[arg(long, default_value = "linuxcnc")]
        dialect: crate::program::Dialect,
        /// Where to write the program [default: standard output].
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

/// A `cnc cam` program to `out` (or standard output), with what was written on standard
/// error.
fn cam_output(made: Result<(String, String), String>, out: Option<PathBuf>) -> ExitCode {
    let (text, summary) = match made {
        Ok(m) => m,
        Err(e) => return fail(e),
    };
    if let Some(path) = out {
        if let Err(e) = std::fs::write(&path, &text) {
            return fail(format!("{}: {e}", path.display()));
        }
        eprintln!("{}: {summary}", path.display());
    } else {
        print!("{text}");
        eprintln!("{summary}");
    }
    ExitCode::SUCCESS
}

/// `X,Y` as two numbers.
fn parse_xy(s: &str) -> Result<[f64; 2], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>().map_err(|e| format!("{x}: {e}")))
        .collect::<Result<_, _>>()?;
    match v[..] {
        [x, y] if x.is_finite() && y.is_finite() => Ok([x, y]),
        _ => Err(format!("{s}: give two numbers, X,Y")),
    }
}

#[derive(Subcommand)]
pub enum LogCommand {
    /// One line per block: seq, kind, source line, degree, control points, feed.
    Show {
        /// A commands.log, or a run directory holding one.
        log: PathBuf,
        /// The blocks as JSON instead.
        #[arg(long)]
        json: bool,
    },
}

#[derive(Subcommand)]
pub enum Role {
    Interpreter {
        #[command(flatten)]
        common: servo_sim::cli::Args,
        #[arg(long)]
        program: Option<PathBuf>,
        #[arg(long)]
        program_name: Option<String>,
        #[arg(long)]
        replay: Option<PathBuf>,
        #[arg(long)]
        salvage: bool,
        /// Run the program this many times in one stream (see `cnc run --repeat`).
        #[arg(long, default_value_t = 1)]
        repeat: u32,
        /// Test aid: wait this many ms before publishing each block (a slow interpreter).
        #[arg(long)]
        throttle_ms: Option<u64>,
        /// Read the program in this dialect (see `cnc run --dialect`).
        #[arg(long)]
        dialect: Option<crate::program::Dialect>,
        /// Where subroutine files are looked for (see `cnc run --subroutine-path`).
        #[arg(long)]
        subroutine_path: Vec<PathBuf>,
        /// The tool table (see `cnc run --tool-table`).
        #[arg(long)]
        tool_table: Option<PathBuf>,
        /// What the program may do beyond its dialect (see `cnc run --dialect-extension`).
        #[arg(long = "dialect-extension")]
        extensions: Vec<crate::program::dialect::Extension>,
        /// The launcher's check of the program (`checked.json`), taken instead of
        /// checking it again where the program's digest, the machine and the period
        /// are those it checked.
        #[arg(long)]
        checked: Option<PathBuf>,
    },
    Interpolator(interpolator::cli::Args),
    ServoSim(servo_sim::cli::Args),
}

fn fail(msg: impl std::fmt::Display) -> ExitCode {
    let _ = std::io::Write::write_fmt(&mut std::io::stderr(), format_args!("cnc: {msg}\n"));
    ExitCode::FAILURE
}

/// Runs the interpreter process from its role arguments.
pub fn run_interpreter(
    common: &servo_sim::cli::Args,
    program: Option<PathBuf>,
    program_name: Option<String>,
    replay: Option<PathBuf>,
    salvage: bool,
) -> ExitCode {
    run_interpreter_streaming(
        common,
        program,
        program_name,
        replay,
        salvage,
        process::Streaming::default(),
    )
}

/// [`run_interpreter`], repeating or pacing the program as `streaming` says.
pub fn run_interpreter_streaming(
    common: &servo_sim::cli::Args,
    program: Option<PathBuf>,
    program_name: Option<String>,
    replay: Option<PathBuf>,
    salvage: bool,
    streaming: process::Streaming,
) -> ExitCode {
    let machine = match shared::machine::load(common.machine.as_deref()) {
        Ok(m) => m,
        Err(e) => return fail(e),
    };
    shared::machine::log_in_force("interpreter", common.machine.as_deref(), &machine);
    shared::stop::install_handler();
    let cfg = process::Config {
        prefix: common.prefix.clone(),
        out_dir: common.out.clone(),
        period_ns: common.period_us * 1000,
        machine,
        program,
        program_name,
        replay,
        salvage,
    };
    match process::run_streaming::<iceoryx2::prelude::ipc::Service>(&cfg, streaming) {
        Ok(s) if s.fault.is_none() => ExitCode::SUCCESS,
        Ok(s) => fail(s.fault.unwrap_or_default()),
        Err(e) => fail(e),
    }
}

/// Hands the page to the desktop's browser, or says where it is when there is no desktop.
fn open_in_browser(page: &std::path::Path) {
    let desktop =
        std::env::var_os("DISPLAY").is_some() || std::env::var_os("WAYLAND_DISPLAY").is_some();
    let opened = desktop
        && std::process::Command::new("xdg-open")
            .arg(page)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
    if !opened {
        eprintln!(
            "cnc report: no desktop browser to open here; the page is {}",
            page.display()
        );
    }
}

/// `cnc check part.stp`: the part's report; with `--estimate` its blocks stepped through
/// the interpolator's engine too.
fn check_step(
    name: &str,
    text: &str,
    machine: &shared::Machine,
    period_us: u64,
    estimate: bool,
    json: bool,
) -> ExitCode {
    let report = match crate::step::check::check_part(name, text, machine) {
        Ok(r) => {
            eprint!(
                "{}",
                process::format_notes(name, &crate::step::check::part_notes(text, machine))
            );
            r
        }
        Err(errors) => {
            eprint!("{errors}");
            return ExitCode::FAILURE;
        }
    };
    if !estimate {
        print!("{report}");
        return ExitCode::SUCCESS;
    }
    let period_ns = period_us * 1000;
    let (blocks, scallop) = match crate::surface_blocks::part_blocks(text, machine, period_ns) {
        Ok(b) => b,
        Err(e) => {
            eprint!("{}", crate::step::format_errors(name, &e));
            return ExitCode::FAILURE;
        }
    };
    match crate::estimate::estimate(&blocks, machine, period_ns) {
        Ok(est) if json => {
            println!("{}", serde_json::to_string_pretty(&est).unwrap_or_default());
            ExitCode::SUCCESS
        }
        Ok(est) => {
            print!("{report}");
            println!(
                "{}: {} blocks; machining time {:.3} s ({} cycles of {} µs), path {:.3} mm, \
                 max scallop {:.2} µm",
                name,
                blocks.len(),
                est.time_s,
                est.cycles,
                period_us,
                est.path_length_mm,
                scallop * 1e3
            );
            ExitCode::SUCCESS
        }
        Err(e) => fail(format!("{name}: estimate: {e}")),
    }
}

pub fn main() -> ExitCode {
    let cli = Cli::parse();
    shared::logging::init();
    match cli.command {
        Command::Run(args) => launch::run(&args),
        Command::Check {
            program,
            machine,
            estimate,
            json,
            period_us,
            dialect,
            subroutine_path,
            tool_table,
            extensions,
        } => {
            let machine = match shared::machine::load(machine.as_deref()) {
                Ok(m) => m,
                Err(e) => return fail(e),
            };
            if let Err(e) = machine.check_period(period_us) {
                return fail(e);
            }
            // A regular UTF-8 file is mapped, not copied (see `mapped`); anything else
            // is read the usual way, with the usual errors.
            let mapped = crate::mapped::MappedText::open(&program);
            let src = match &mapped {
                Some(_) => Source {
                    name: program.display().to_string(),
                    text: String::new(),
                },
                None => match Source::load(Some(&program)) {
                    Ok(s) => s,
                    Err(e) => return fail(e),
                },
            };
            let text = mapped.as_ref().map_or(src.text.as_str(), |m| m.as_str());
            let period_ns = period_us * 1000;
            if crate::step::check::is_step_file(&src.name, text) {
                return check_step(&src.name, text, &machine, period_us, estimate, json);
            }
            // Subroutine files are looked for beside the program first, as LinuxCNC
            // looks in the directory of the program it opened.
            let beside = program.parent().map(std::path::Path::to_path_buf);
            let tools = match tool_table
                .as_deref()
                .map(crate::program::tools::ToolTable::load)
                .transpose()
            {
                Ok(t) => t,
                Err(e) => return fail(e),
            };
            let opts = crate::program::Options {
                dialect,
                subroutine_dirs: beside.into_iter().chain(subroutine_path).collect(),
                tools,
                offset_tolerance_mm: None,
                uncompensated: false,
                // (The machine's, set where the program is checked.)
                blend_tolerance_mm: 0.0,
                extensions,
            };
            // Read, planned and checked window by window: only a window of the program
            // is held at a time, and the pages of the file read are given back.
            let mut read = |from: usize, to: usize| {
                if let Some(m) = &mapped {
                    m.release(from, to);
                }
            };
            let checked = if estimate {
                process::check_estimated(text, &opts, &machine, period_ns, json, &mut read)
            } else {
                process::check_windows(text, &opts, &machine, period_ns, &mut |_, _| {}, &mut read)
                    .map(|p| (p, None))
            };
            if let Ok((planned, _)) = &checked {
                eprint!("{}", process::format_notes(&src.name, &planned.notes));
                eprint!("{}", process::format_windows(&src.name, planned, &machine));
            }
            match checked {
                Ok((planned, Some(est))) => match est {
                    Ok(est) if json => {
                        println!("{}", serde_json::to_string_pretty(&est).unwrap_or_default());
                        ExitCode::SUCCESS
                    }
                    Ok(est) => {
                        println!(
                            "{}: ok, {} dialect, {} blocks; machining time {:.3} s ({} cycles of {} µs), path {:.3} mm",
                            src.name,
                            planned.dialect,
                            planned.blocks,
                            est.time_s,
                            est.cycles,
                            period_us,
                            est.path_length_mm
                        );
                        ExitCode::SUCCESS
                    }
                    Err(e) => fail(format!("{}: estimate: {e}", src.name)),
                },
                Ok((planned, None)) => {
                    println!(
                        "{}: ok, {} dialect, {} blocks",
                        src.name, planned.dialect, planned.blocks
                    );
                    ExitCode::SUCCESS
                }
                Err(diags) => {
                    eprint!("{}", process::format_diagnostics(&src.name, &diags));
                    ExitCode::FAILURE
                }
            }
        }
        Command::Replay(args) => crate::replay::replay(&args),
        Command::Report { run_dir, out, open } => {
            match crate::html::write(&run_dir, out.as_deref()) {
                Ok(page) => {
                    println!("{}", page.display());
                    if open {
                        open_in_browser(&page);
                    }
                    ExitCode::SUCCESS
                }
                Err(e) => fail(e),
            }
        }
        Command::Log(LogCommand::Show { log, json }) => crate::replay::show(&log, json),
        Command::Machine { from_ini, out } => {
            let text = match from_ini {
                None => shared::Machine::default_toml(),
                Some(ini) => {
                    let made = std::fs::read_to_string(&ini)
                        .map_err(|e| format!("{}: {e}", ini.display()))
                        .and_then(|t| {
                            // `from_ini` names each `#INCLUDE`d file by its path from
                            // here (beside the file that includes it).
                            let include = |path: &str| {
                                std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))
                            };
                            shared::machine_ini::from_ini(&t, &ini.display().to_string(), &include)
                        });
                    match made {
                        Ok(m) => {
                            for w in &m.warnings {
                                eprintln!("warning: {w}");
                            }
                            m.toml
                        }
                        Err(e) => return fail(e),
                    }
                }
            };
            match out {
                None => print!("{text}"),
                Some(path) => {
                    if let Err(e) = std::fs::write(&path, text) {
                        return fail(format!("{}: {e}", path.display()));
                    }
                }
            }
            ExitCode::SUCCESS
        }
        Command::Cam(CamCommand::Ellipse {
            a,
            b,
            centre,
            offset,
            tolerance,
            feed,
            depth,
            dialect,
            out,
        }) => {
            let job = crate::cam::EllipseJob {
                a,
                b,
                centre,
                offset,
                tolerance,
                feed,
                depth,
                fanuc: dialect == crate::program::Dialect::Fanuc,
            };
            cam_output(crate::cam::ellipse_program(&job), out)
        }
        Command::Cam(CamCommand::Curves {
            step,
            feed,
            depth,
            project,
            dialect,
            out,
        }) => {
            let text = match std::fs::read_to_string(&step) {
                Ok(t) => t,
                Err(e) => return fail(format!("{}: {e}", step.display())),
            };
            let job = crate::cam::curves::CurvesJob {
                cut: crate::cam::Job {
                    feed,
                    depth,
                    fanuc: dialect == crate::program::Dialect::Fanuc,
                },
                project,
            };
            let name = step.display().to_string();
            match crate::cam::curves::curves_program(&text, &name, &job) {
                // The errors are whole lines already (`file:line: #id: rule: message`).
                Err(e) => {
                    eprint!("{e}");
                    ExitCode::FAILURE
                }
                ok => cam_output(ok, out),
            }
        }
        Command::LatencyTest(args) => match interpolator::cli::latency_test(&args) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => fail(e),
        },
        Command::Role(Role::Interpreter {
            common,
            program,
            program_name,
            replay,
            salvage,
            repeat,
            throttle_ms,
            dialect,
            subroutine_path,
            tool_table,
            extensions,
            checked,
        }) => run_interpreter_streaming(
            &common,
            program,
            program_name,
            replay,
            salvage,
            process::Streaming {
                repeat,
                throttle: throttle_ms.map(std::time::Duration::from_millis),
                hold_before_reading: None,
                dialect,
                subroutine_dirs: subroutine_path,
                tool_table,
                extensions,
                checked,
            },
        ),
        Command::Role(Role::Interpolator(args)) => match interpolator::cli::run(&args) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => fail(e),
        },
        Command::Role(Role::ServoSim(args)) => {
            let machine = match shared::machine::load(args.machine.as_deref()) {
                Ok(m) => m,
                Err(e) => return fail(e),
            };
            match servo_sim::cli::run(&args, machine) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => fail(e),
            }
        }
    }
}
