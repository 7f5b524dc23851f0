//! Publishing command blocks to the interpolator with back-pressure: a block counts as
//! sent only when it reached the interpolator's queue; a full queue (or a subscriber not
//! yet attached) means wait and retry, never drop. Each block is appended to the command
//! log as it is sent, and logged at `debug` (`block published`).
//!
//! A dead interpolator is noticed here too: while waiting, the publisher asks iceoryx2 every
//! few milliseconds to remove dead nodes from the block service, so the interpolator's
//! subscriber leaves the service when its process has died.

use iceoryx2::prelude::*;
use shared::cmdlog::CommandLog;
use shared::ipc::{self, err, IpcError};
use shared::protocol::{BlockKind, CommandBlock, RunState, Services};
use std::time::{Duration, Instant};

/// How the interpolator finished, as its status reported it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Finish {
    Done,
    Fault,
}

/// How often a waiting publisher looks for a dead interpolator.
const LIVENESS_EVERY: Duration = Duration::from_millis(5);

/// Test aid: wait this long before publishing each block (a slow interpreter), so tests
/// can starve the interpolator on purpose. `None` in normal runs.
#[derive(Debug, Clone, Copy, Default)]
pub struct Pace {
    pub throttle: Option<Duration>,
}

/// One `debug` line per block the interpolator's queue took.
fn log_sent(b: &CommandBlock) {
    let kind = BlockKind::from_code(b.kind).map_or("unknown", BlockKind::name);
    tracing::debug!(
        seq = b.seq,
        kind = %kind,
        line = b.source_line,
        length_mm = b.length_mm,
        feed_mm_per_min = b.feed_mm_per_min,
        "block published"
    );
}

/// The interpreter's ports: blocks out, the interpolator's status in. Opened before the
/// program is read and planned, so the interpolator knows an interpreter is there and
/// waits for its first block however long the planning takes.
pub struct Link<S: Service> {
    _node: Node<S>,
    service: ipc::PubSub<S, CommandBlock>,
    publisher: iceoryx2::port::publisher::Publisher<S, CommandBlock, ()>,
    status_sub: iceoryx2::port::subscriber::Subscriber<S, shared::protocol::Status, ()>,
}

impl<S: Service> Link<S> {
    pub fn open(prefix: &str) -> Result<Self, IpcError> {
        let svc = Services::new(prefix);
        let node = ipc::node::<S>("interpreter")?;
        let service = ipc::blocks(&node, &svc)?;
        let publisher = service
            .publisher_builder()
            .create()
            .map_err(|e| err("block publisher", e))?;
        let status = ipc::status(&node, &svc)?;
        let status_sub = status
            .subscriber_builder()
            .create()
            .map_err(|e| err("status subscriber", e))?;
        tracing::debug!(
            blocks = %svc.blocks(),
            status = %svc.status(),
            "interpreter: shared-memory services open (blocks out, the interpolator's status in)"
        );
        Ok(Link {
            _node: node,
            service,
            publisher,
            status_sub,
        })
    }

    /// Whether the interpolator's block port is there (dead nodes removed first).
    pub fn interpolator_there(&self) -> bool {
        let _ = self.service.try_cleanup_dead_nodes();
        self.service.dynamic_config().number_of_subscribers() > 0
    }
}

/// Sends every block in order, then waits for the interpolator to report done or fault.
/// Returns how it finished and how many blocks were sent.
pub fn send<S: Service>(
    link: &Link<S>,
    blocks: impl IntoIterator<Item = CommandBlock>,
    mut log: Option<&mut CommandLog>,
    start_timeout: Duration,
    pace: Pace,
) -> Result<(Finish, u64), IpcError> {
    let Link {
        service,
        publisher,
        status_sub,
        ..
    } = link;
    let mut last_state = RunState::Idle;
    let mut last_cycle: Option<u64> = None;
    let poll_status = |last: &mut RunState, cycle: &mut Option<u64>| -> Result<(), IpcError> {
        while let Ok(Some(s)) = status_sub.receive() {
            *last = s
                .validate()
                .map_err(|e| IpcError(format!("bad status from the interpolator: {e}")))?;
            *cycle = Some(s.cycle);
        }
        Ok(())
    };
    // Whether the interpolator's subscriber is gone, dead ones removed first (rate-limited).
    let mut last_check = Instant::now();
    let mut interpolator_gone = || {
        if last_check.elapsed() >= LIVENESS_EVERY {
            last_check = Instant::now();
            let _ = service.try_cleanup_dead_nodes();
        }
        service.dynamic_config().number_of_subscribers() == 0
    };
    let gone_text = |what: String, cycle: Option<u64>| {
        IpcError(format!(
            "the interpolator is gone (its process ended or died) {what}{}",
            cycle.map_or(String::new(), |c| format!(
                "; its last status was cycle {c}"
            ))
        ))
    };
    let started = Instant::now();
    let mut connected = false;
    let mut sent = 0u64;
    for b in blocks {
        if let Some(d) = pace.throttle {
            std::thread::sleep(d);
        }
        loop {
            let sample = publisher
                .loan_uninit()
                .map_err(|e| err("loaning a block", e))?;
            let delivered = sample
                .write_payload(b)
                .send()
                .map_err(|e| err("sending a block", e))?;
            if delivered > 0 {
                connected = true;
                break;
            }
            poll_status(&mut last_state, &mut last_cycle)?;
            if last_state == RunState::Fault {
                return Ok((Finish::Fault, sent));
            }
            if shared::stop::terminate_requested() {
                return Err(IpcError(format!(
                    "stopped on request before block {}",
                    b.seq
                )));
            }
            if !connected && started.elapsed() > start_timeout {
                return Err(IpcError("no interpolator took the first block".into()));
            }
            if connected && interpolator_gone() {
                return Err(gone_text(format!("before block {}", b.seq), last_cycle));
            }
            std::thread::sleep(Duration::from_micros(500));
        }
        sent += 1;
        log_sent(&b);
        if let Some(l) = log.as_deref_mut() {
            l.append(&b)
                .map_err(|e| IpcError(format!("writing commands.log: {e}")))?;
        }
    }
    // Keep the publisher (and the blocks in its memory) alive until they are executed.
    loop {
        poll_status(&mut last_state, &mut last_cycle)?;
        if last_state == RunState::Done {
            return Ok((Finish::Done, sent));
        }
        if last_state == RunState::Fault {
            return Ok((Finish::Fault, sent));
        }
        if interpolator_gone() {
            // It may have finished in the meantime: its final status is kept (history 1).
            poll_status(&mut last_state, &mut last_cycle)?;
            match last_state {
                RunState::Done => return Ok((Finish::Done, sent)),
                RunState::Fault => return Ok((Finish::Fault, sent)),
                _ => return Err(gone_text("before the program end".into(), last_cycle)),
            }
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}
