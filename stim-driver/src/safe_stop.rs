//! `stim-driver safe-stop`: NMT stop on the bus, from a fresh process.
//!
//! systemd runs it after the driver has stopped for any reason (`ExecStopPost=`), so it
//! needs nothing but the interface: it sends NMT stop addressed to the stimulator's node
//! and NMT stop to all nodes (node 0), each retried while the transmit queue is full for
//! up to [`RETRY_BUDGET`]. The stimulator's own heartbeat watchdog is the independent
//! second line when even this cannot reach the bus.

use std::time::Duration;

use fes_can::{EncodeError, Message, Nmt, NmtCommand, Nodes};

use crate::tx::{BusTx, CanTx, RetryPolicy, TxError};

/// How long each frame is retried while the transmit queue is full.
pub const RETRY_BUDGET: Duration = Duration::from_millis(200);
/// Pause between retries.
pub const RETRY_INTERVAL: Duration = Duration::from_millis(1);

/// The stop could not be sent.
#[derive(Debug, thiserror::Error)]
pub enum SafeStopError {
    /// The interface could not be opened.
    #[error("cannot open CAN interface {iface:?}: {source}")]
    Open {
        /// Interface.
        iface: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// The frame could not be encoded (a bad node id).
    #[error("NMT stop: {0}")]
    Encode(#[from] EncodeError),
    /// Neither NMT stop reached the transmit queue.
    #[error("NMT stop could not be written on {iface:?}: {error}")]
    Tx {
        /// Interface.
        iface: String,
        /// The last write's error.
        error: TxError,
    },
}

/// The NMT stop frames, in the order sent: to `nodes.stim()`, then to all nodes.
pub fn stop_frames(nodes: &Nodes) -> Result<[fes_can::Frame; 2], EncodeError> {
    let stop = |node| {
        Message::Nmt(Nmt {
            command: NmtCommand::Stop,
            node,
        })
        .encode_for(nodes)
    };
    Ok([stop(nodes.stim())?, stop(0)?])
}

/// Sends the stop frames through `tx`; succeeds when at least one was written (each
/// stops the stimulator), and returns how many were.
pub fn send_stop(tx: &mut impl CanTx, nodes: &Nodes) -> Result<usize, (usize, TxError)> {
    let frames = stop_frames(nodes).map_err(|_| {
        (
            0,
            TxError::Failed {
                errno: libc::EINVAL,
            },
        )
    })?;
    let mut written = 0;
    let mut last_error = None;
    for f in &frames {
        match tx.send(f) {
            Ok(_) => written += 1,
            Err(e) => last_error = Some(e),
        }
    }
    match (written, last_error) {
        (0, Some(e)) => Err((0, e)),
        _ => Ok(written),
    }
}

/// Opens `iface` and sends NMT stop to the stimulator at `nodes` and to all nodes.
pub fn safe_stop(iface: &str, nodes: &Nodes) -> Result<usize, SafeStopError> {
    stop_frames(nodes)?;
    let retry = RetryPolicy {
        budget_ns: RETRY_BUDGET.as_nanos() as u64,
        interval_ns: RETRY_INTERVAL.as_nanos() as u64,
    };
    let mut tx = BusTx::open(iface, retry).map_err(|source| SafeStopError::Open {
        iface: iface.to_owned(),
        source,
    })?;
    send_stop(&mut tx, nodes).map_err(|(_, error)| SafeStopError::Tx {
        iface: iface.to_owned(),
        error,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tx::CountingSink;

    #[test]
    fn both_frames_are_canopen_nmt_stop() {
        let nodes = Nodes::new(1, 0x22).unwrap();
        let [a, b] = stop_frames(&nodes).unwrap();
        // CANopen NMT: identifier 0x000, [command 0x02 = stop, node].
        assert_eq!((a.id, a.payload()), (0x000, &[0x02, 0x22][..]));
        assert_eq!((b.id, b.payload()), (0x000, &[0x02, 0x00][..]));
        let mut sink = CountingSink::new(0x110);
        assert_eq!(send_stop(&mut sink, &nodes), Ok(2));
        sink.fail_with = Some(TxError::LinkDown {
            errno: libc::ENETDOWN,
        });
        assert!(matches!(
            send_stop(&mut sink, &nodes),
            Err((0, TxError::LinkDown { .. }))
        ));
    }
}
