//! Machining-time estimate: the planned blocks stepped through the interpolator's own
//! engine, in this process, cycle by cycle. The engine is the very code the interpolator
//! runs and its output does not depend on the clock, so the estimate is exactly the
//! `time_s` a `--clock sim` (or real) run of the same program and machine reports.

use interpolator::engine::{BlockSource, Engine, Limits, TickState};
use serde::Serialize;
use shared::protocol::{CommandBlock, FLAG_RAPID};
use shared::Machine;

/// Time spent on one source line.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct LineTime {
    pub line: u32,
    pub cycles: u64,
    pub time_s: f64,
    pub length_mm: f64,
    pub rapid: bool,
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Estimate {
    pub period_ns: u64,
    pub cycles: u64,
    pub time_s: f64,
    pub path_length_mm: f64,
    /// Per source line, in program order (consecutive cycles of one line are one entry).
    pub moves: Vec<LineTime>,
}

/// The blocks handed to the engine, with the source lines of the rapid ones noted as they
/// go.
struct Feed<I> {
    blocks: I,
    rapid_lines: std::collections::HashSet<u32>,
    /// The lines' times are wanted (else the rapid lines are not noted).
    per_line: bool,
}

impl<I: Iterator<Item = CommandBlock>> BlockSource for Feed<I> {
    fn next_block(&mut self) -> Option<CommandBlock> {
        let b = self.blocks.next()?;
        if self.per_line && b.flags & FLAG_RAPID != 0 {
            self.rapid_lines.insert(b.source_line);
        }
        Some(b)
    }
}

/// Steps the blocks to the program end. An engine fault (which a checked program cannot
/// cause) is returned as its message.
pub fn estimate(
    blocks: &[CommandBlock],
    machine: &Machine,
    period_ns: u64,
) -> Result<Estimate, String> {
    estimate_up_to(blocks, machine, period_ns, u64::MAX)?
        .ok_or_else(|| "the program did not end in 2^64 cycles".to_string())
}

/// [`estimate`], stopped after `max_cycles` cycles: `None` if the program has not ended
/// by then (the property tests step long programs only so far).
pub fn estimate_up_to(
    blocks: &[CommandBlock],
    machine: &Machine,
    period_ns: u64,
    max_cycles: u64,
) -> Result<Option<Estimate>, String> {
    estimate_of(blocks.iter().copied(), machine, period_ns, max_cycles)
}

/// [`estimate_up_to`] of the blocks as an iterator yields them: a program held compact
/// is made into command blocks one at a time.
pub fn estimate_of(
    blocks: impl Iterator<Item = CommandBlock>,
    machine: &Machine,
    period_ns: u64,
    max_cycles: u64,
) -> Result<Option<Estimate>, String> {
    stepped(blocks, machine, period_ns, max_cycles, true)
}

/// [`estimate_of`], with the time of each source line (`per_line`) or without (then
/// [`Estimate::moves`] is empty, and a program of ten million lines is not ten million
/// entries).
fn stepped(
    blocks: impl Iterator<Item = CommandBlock>,
    machine: &Machine,
    period_ns: u64,
    max_cycles: u64,
    per_line: bool,
) -> Result<Option<Estimate>, String> {
    let lim = Limits::new(machine, period_ns);
    let mut engine = Engine::new(lim, [0.0; 3]);
    let mut src = Feed {
        blocks,
        rapid_lines: Default::default(),
        per_line,
    };
    let mut moves: Vec<LineTime> = Vec::new();
    let mut cycles = 0u64;
    let mut last = engine.position();
    let mut total = 0.0;
    loop {
        let t = engine.tick(&mut src).map_err(|f| f.to_string())?;
        cycles += 1;
        let d = shared::path::norm([
            t.pos_mm[0] - last[0],
            t.pos_mm[1] - last[1],
            t.pos_mm[2] - last[2],
        ]);
        last = t.pos_mm;
        total += d;
        match moves.last_mut() {
            _ if !per_line => {}
            Some(m) if m.line == t.source_line => {
                m.cycles += 1;
                m.length_mm += d;
            }
            _ => moves.push(LineTime {
                line: t.source_line,
                cycles: 1,
                time_s: 0.0,
                length_mm: d,
                rapid: t.rapid,
            }),
        }
        match t.state {
            TickState::Done => break,
            TickState::Running if cycles >= max_cycles => return Ok(None),
            TickState::Running => {}
            // All blocks are in hand from the start, so the engine can only starve if the
            // block list lacks its end.
            TickState::Starved => return Err("the program has no end block".into()),
        }
    }
    // The source lines with a rapid block, noted as the blocks went in (looking through
    // every block for each line made a long program's estimate quadratic: 100 000 lines
    // of `G1` took 73 s, all but 5 of them here).
    for m in &mut moves {
        m.time_s = (m.cycles * period_ns) as f64 * 1e-9;
        m.rapid = m.rapid || src.rapid_lines.contains(&m.line);
    }
    Ok(Some(Estimate {
        period_ns,
        cycles,
        time_s: (cycles * period_ns) as f64 * 1e-9,
        path_length_mm: total,
        moves,
    }))
}

/// The windows of blocks a program is planned in ([`crate::window`]), as they come
/// over a channel with the sequence number of each window's first block.
type Windows = std::sync::mpsc::Receiver<(Vec<crate::blocks::Block>, usize)>;

/// [`estimate_of`] the blocks of the windows that come over `windows` until it closes,
/// each block made its command block as it is stepped; the time of each source line
/// only if `per_line`. Block 0 coming again means the
/// program is being read again from its start (see [`crate::window::Stream`]): the
/// stepping starts again with it.
pub fn estimate_windows(
    windows: &Windows,
    machine: &Machine,
    period_ns: u64,
    per_line: bool,
) -> Result<Estimate, String> {
    let mut from = Stepped {
        windows,
        window: Vec::new().into_iter(),
        seq: 0,
        held: None,
        started: false,
        again: false,
    };
    loop {
        let est = stepped(&mut from, machine, period_ns, u64::MAX, per_line);
        if !std::mem::take(&mut from.again) {
            return est.and_then(|e| {
                e.ok_or_else(|| "the program did not end in 2^64 cycles".to_string())
            });
        }
        from.started = false;
        from.window = Vec::new().into_iter();
    }
}

/// The command blocks of the windows of [`estimate_windows`], one at a time; ends
/// (with `again`) where block 0 comes again.
struct Stepped<'a> {
    windows: &'a Windows,
    window: std::vec::IntoIter<crate::blocks::Block>,
    /// The sequence number of the next block of `window`.
    seq: u64,
    /// A window that came after the stepping was ended for it.
    held: Option<(Vec<crate::blocks::Block>, usize)>,
    started: bool,
    again: bool,
}

impl Iterator for Stepped<'_> {
    type Item = CommandBlock;

    fn next(&mut self) -> Option<CommandBlock> {
        loop {
            if let Some(b) = self.window.next() {
                self.seq += 1;
                return Some(b.command(self.seq - 1));
            }
            let (blocks, first) = self.held.take().or_else(|| self.windows.recv().ok())?;
            if first == 0 && self.started {
                self.held = Some((blocks, first));
                self.again = true;
                return None;
            }
            self.started = true;
            self.window = blocks.into_iter();
            self.seq = first as u64;
        }
    }
}
