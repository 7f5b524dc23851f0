//! Publishing command blocks to the interpolator with back-pressure: a block counts as
//! sent only when it reached the interpolator's queue; a full queue (or a subscriber not
//! yet attached) means wait and retry, never drop. Each block is appended to the command
//! log as it is sent.

use iceoryx2::prelude::*;
use shared::cmdlog::CommandLog;
use shared::ipc::{self, err, IpcError};
use shared::protocol::{CommandBlock, RunState, Services};
use std::time::{Duration, Instant};

/// How the interpolator finished, as its status reported it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Finish {
    Done,
    Fault,
}

/// Sends every block in order, then waits for the interpolator to report done or fault.
pub fn publish<S: Service>(
    prefix: &str,
    blocks: &[CommandBlock],
    mut log: Option<&mut CommandLog>,
    start_timeout: Duration,
) -> Result<Finish, IpcError> {
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
    let mut last_state = RunState::Idle;
    let poll_status = |last: &mut RunState| -> Result<(), IpcError> {
        while let Ok(Some(s)) = status_sub.receive() {
            *last = s
                .validate()
                .map_err(|e| IpcError(format!("bad status from the interpolator: {e}")))?;
        }
        Ok(())
    };
    let started = Instant::now();
    let mut connected = false;
    for b in blocks {
        loop {
            let sample = publisher
                .loan_uninit()
                .map_err(|e| err("loaning a block", e))?;
            let delivered = sample
                .write_payload(*b)
                .send()
                .map_err(|e| err("sending a block", e))?;
            if delivered > 0 {
                connected = true;
                break;
            }
            poll_status(&mut last_state)?;
            if last_state == RunState::Fault {
                return Ok(Finish::Fault);
            }
            if shared::stop::requested() {
                return Err(IpcError(format!(
                    "stopped on request before block {}",
                    b.seq
                )));
            }
            if !connected && started.elapsed() > start_timeout {
                return Err(IpcError("no interpolator took the first block".into()));
            }
            if connected && service.dynamic_config().number_of_subscribers() == 0 {
                return Err(IpcError(format!(
                    "the interpolator went away before block {}",
                    b.seq
                )));
            }
            std::thread::sleep(Duration::from_micros(500));
        }
        if let Some(l) = log.as_deref_mut() {
            l.append(b)
                .map_err(|e| IpcError(format!("writing commands.log: {e}")))?;
        }
    }
    // Keep the publisher (and the blocks in its memory) alive until they are executed.
    loop {
        poll_status(&mut last_state)?;
        if last_state == RunState::Done {
            return Ok(Finish::Done);
        }
        if last_state == RunState::Fault {
            return Ok(Finish::Fault);
        }
        if service.dynamic_config().number_of_subscribers() == 0 {
            return Err(IpcError(
                "the interpolator went away before the program end".into(),
            ));
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}
