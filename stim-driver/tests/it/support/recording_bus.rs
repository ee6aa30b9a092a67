#![allow(dead_code)] // each test binary uses part of it
//! A CAN transmitter for the forward path's tests on simulated time: it records every
//! frame with the time it was written and can be told to fail; and the stimulator's
//! STATUS as the receive side hands it to the forward path.

use std::cell::{Cell, RefCell};
use std::rc::Rc;

use fes_can::{ErrorCode, Frame, Message, NmtCommand, Status, StimState};
use stim_driver::event::BusEvent;
use stim_driver::tx::{CanTx, TxDone, TxError};

/// A bus that records every frame with the simulated time it was sent at.
#[derive(Clone, Default)]
pub struct Bus {
    pub now: Rc<Cell<u64>>,
    pub frames: Rc<RefCell<Vec<(u64, Frame)>>>,
    pub fail: Rc<Cell<Option<TxError>>>,
    /// The last `contraction_ahead` the driver passed on.
    pub ahead: Rc<Cell<bool>>,
}

impl CanTx for Bus {
    fn send(&mut self, frame: &Frame) -> Result<TxDone, TxError> {
        if let Some(e) = self.fail.get() {
            return Err(e);
        }
        self.frames.borrow_mut().push((self.now.get(), *frame));
        Ok(TxDone {
            retries: 0,
            written_ns: self.now.get(),
            write_ns: 0,
        })
    }

    fn contraction_ahead(&mut self, ahead: bool) {
        self.ahead.set(ahead);
    }
}

impl Bus {
    pub fn messages(&self) -> Vec<(u64, Message)> {
        self.frames
            .borrow()
            .iter()
            .map(|(t, f)| {
                (
                    *t,
                    fes_can::decode(u32::from(f.id), f.payload()).expect("driver frames decode"),
                )
            })
            .collect()
    }

    pub fn nmt(&self) -> Vec<(u64, NmtCommand)> {
        self.messages()
            .into_iter()
            .filter_map(|(t, m)| match m {
                Message::Nmt(n) => Some((t, n.command)),
                _ => None,
            })
            .collect()
    }

    pub fn pulses(&self) -> Vec<(u64, fes_can::Pulse)> {
        self.messages()
            .into_iter()
            .filter_map(|(t, m)| match m {
                Message::Pulse(p) => Some((t, p)),
                _ => None,
            })
            .collect()
    }

    /// A STATUS from a stimulator that has applied every PULSE written so far (those
    /// still recorded: [`Self::clear`] forgets them).
    pub fn honest_status(&self, state: StimState, config_id: u8) -> BusEvent {
        status_delivered(state, config_id, self.pulses().len() as u32)
    }

    pub fn clear(&self) {
        self.frames.borrow_mut().clear();
    }
}

/// The CONFIG_APPLIED pages a conforming stimulator answers a complete CONFIG with.
pub fn applied(limits: &fes_can::StimLimits, config_id: u8) -> Vec<BusEvent> {
    limits
        .to_pages(config_id)
        .into_iter()
        .map(BusEvent::ConfigApplied)
        .collect()
}

/// A STATUS event from the stimulator: `state`, confirming configuration `config_id`,
/// no pulse applied yet.
pub fn status(state: StimState, config_id: u8) -> BusEvent {
    status_delivered(state, config_id, 0)
}

/// A STATUS event reporting `delivered` pulses applied (modulo 2^24, as STATUS carries it).
pub fn status_delivered(state: StimState, config_id: u8, delivered: u32) -> BusEvent {
    BusEvent::Status(Status {
        state,
        counter: 0,
        last_error: ErrorCode::NoError,
        pulses_delivered: delivered & 0xFF_FFFF,
        rejected: 0,
        config_id,
    })
}
