//! The interpreter process: read and check the program, build and plan the blocks, log
//! and publish them, report.

use crate::parse::Diagnostic;
use crate::publish::{publish, Finish};
use crate::report::InterpreterSummary;
use crate::{blocks, program};
use iceoryx2::prelude::Service;
use shared::cmdlog::CommandLog;
use shared::protocol::{BlockKind, CommandBlock};
use shared::Machine;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The built-in demonstration program.
pub const DEMO: &str = include_str!("demo.ngc");
/// The name the demo goes by in reports and messages.
pub const DEMO_NAME: &str = "demo.ngc";

/// A program's text and the name its diagnostics use.
pub struct Source {
    pub name: String,
    pub text: String,
}

impl Source {
    /// The file at `path`, or the built-in demo when there is none.
    pub fn load(path: Option<&Path>) -> Result<Source, String> {
        match path {
            None => Ok(Source {
                name: DEMO_NAME.into(),
                text: DEMO.into(),
            }),
            Some(p) => std::fs::read(p)
                .map_err(|e| format!("{}: {e}", p.display()))
                .map(|bytes| Source {
                    name: p.display().to_string(),
                    text: String::from_utf8_lossy(&bytes).into_owned(),
                }),
        }
    }
}

/// Every problem of a program as `NAME:LINE:COL: message` lines.
pub fn format_diagnostics(name: &str, diags: &[Diagnostic]) -> String {
    diags
        .iter()
        .map(|d| format!("{name}:{}:{}: {}\n", d.line, d.col, d.message))
        .collect()
}

/// Reads, checks, builds and plans: the blocks as they will be sent.
pub fn compile(
    text: &str,
    machine: &Machine,
    period_ns: u64,
) -> Result<(program::Program, Vec<CommandBlock>), Vec<Diagnostic>> {
    let prog = program::interpret(text)?;
    let mut blocks = blocks::build(&prog.moves, machine);
    blocks::plan(&mut blocks, machine, period_ns);
    // Nothing leaves this process unless a receiver would accept it.
    let bad: Vec<Diagnostic> = blocks
        .iter()
        .filter_map(|b| {
            b.validate().err().map(|e| Diagnostic {
                line: b.source_line,
                col: 1,
                message: format!("internal: {e}"),
            })
        })
        .collect();
    if bad.is_empty() {
        Ok((prog, blocks))
    } else {
        Err(bad)
    }
}

#[derive(Debug, Clone)]
pub struct Config {
    pub prefix: String,
    pub out_dir: PathBuf,
    pub period_ns: u64,
    pub machine: Machine,
    pub program: Option<PathBuf>,
    /// Name to report the program under (the launcher passes the user's path).
    pub program_name: Option<String>,
    /// Replay this command log instead of reading a program.
    pub replay: Option<PathBuf>,
    /// With `replay`: run the intact records of a damaged log, then stop.
    pub salvage: bool,
}

/// A command log ready to replay.
pub struct Replay {
    pub header: shared::cmdlog::Header,
    pub blocks: Vec<CommandBlock>,
    /// What was wrong with a salvaged log: its intact blocks run, then a program end.
    pub salvaged: Option<String>,
}

/// The blocks of a command log to replay. A damaged log is refused, unless `salvage`:
/// then its intact records run, followed by a program end so the machine stops there.
pub fn load_replay(path: &Path, salvage: bool) -> Result<Replay, String> {
    let parsed = shared::cmdlog::read(path)?;
    let mut blocks = parsed.blocks;
    let salvaged = match parsed.damage {
        None => None,
        Some(damage) if !salvage => {
            return Err(format!(
                "{}: {damage}; nothing replayed (--salvage replays the {} intact blocks before it)",
                path.display(),
                blocks.len()
            ))
        }
        Some(damage) => {
            if blocks
                .last()
                .is_some_and(|b| b.kind == BlockKind::ProgramEnd as u32)
            {
                blocks.pop();
            }
            let note = format!(
                "salvaged {}: {damage}; the {} intact blocks before it ran, then a stop",
                path.display(),
                blocks.len()
            );
            blocks.push(CommandBlock::empty(
                BlockKind::ProgramEnd,
                blocks.len() as u64,
                0,
            ));
            Some(note)
        }
    };
    Ok(Replay {
        header: parsed.header,
        blocks,
        salvaged,
    })
}

/// Runs the interpreter until the interpolator reports the end; writes `commands.log` and
/// `interpreter.json`.
pub fn run<S: Service>(cfg: &Config) -> Result<InterpreterSummary, String> {
    let mut salvaged = None;
    let (name, blocks, messages) = match &cfg.replay {
        Some(log) => {
            let r = load_replay(log, cfg.salvage)?;
            salvaged = r.salvaged;
            (r.header.program, r.blocks, Vec::new())
        }
        None => {
            let src = Source::load(cfg.program.as_deref())?;
            let name = cfg.program_name.clone().unwrap_or(src.name.clone());
            let (prog, blocks) = compile(&src.text, &cfg.machine, cfg.period_ns)
                .map_err(|d| format_diagnostics(&name, &d))?;
            (name, blocks, prog.messages)
        }
    };
    for (line, m) in &messages {
        tracing::info!("{name}:{line}: MSG {m}");
    }
    let mut log = CommandLog::create(
        &cfg.out_dir.join("commands.log"),
        cfg.period_ns,
        cfg.machine.hash(),
        &name,
    )
    .map_err(|e| format!("creating commands.log: {e}"))?;
    let result = publish::<S>(
        &cfg.prefix,
        &blocks,
        Some(&mut log),
        Duration::from_secs(20),
    );
    log.finish()
        .map_err(|e| format!("writing commands.log: {e}"))?;
    let fault = match result {
        Ok(Finish::Done) => None,
        Ok(Finish::Fault) => Some("the interpolator stopped with a fault".to_string()),
        Err(e) => Some(e.to_string()),
    };
    let summary = InterpreterSummary {
        outcome: if fault.is_some() { "fault" } else { "done" }.into(),
        fault,
        pid: std::process::id(),
        program: name,
        blocks: blocks.len(),
        messages,
        salvaged,
    };
    let text = serde_json::to_string_pretty(&summary).map_err(|e| e.to_string())?;
    std::fs::write(cfg.out_dir.join("interpreter.json"), text)
        .map_err(|e| format!("writing interpreter.json: {e}"))?;
    Ok(summary)
}
