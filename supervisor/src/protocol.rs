//! The control protocol between the operator's CLI and the supervisor daemon: one JSON
//! object per line over a Unix stream socket, versioned by `v`.
//!
//! ```text
//! -> {"v":1,"id":1,"command":{"kind":"set","force":0.4,"rate_per_s":5.0}}
//! <- {"v":1,"id":1,"ok":true,"message":"reference 0.4 at 5 /s"}
//! -> {"v":1,"id":2,"command":{"kind":"set","force":1.4}}
//! <- {"v":1,"id":2,"ok":false,"error":"force 1.4 is outside [0, 1] (normalised force)"}
//! ```
//!
//! Commands: `status`, `set`, `profile`, `stop`, `arm`, `outer_loop`. A request is at most
//! [`MAX_LINE`] bytes; unknown fields, a wrong version, invalid UTF-8 or JSON are refused
//! with an error naming the problem. [`parse_request`] never panics (property test over
//! arbitrary bytes).

use serde::{Deserialize, Serialize};

use crate::core::FaultCause;

use crate::profile::ProfileSpec;

/// The protocol version this build speaks.
pub const VERSION: u32 = 1;
/// Longest request line, bytes (newline excluded).
pub const MAX_LINE: usize = 64 * 1024;

/// One operator command.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Command {
    /// Report the state; changes nothing.
    Status,
    /// Hold a constant reference `force`, reached at `rate_per_s` (default: configured).
    Set {
        /// Normalised force, [0, max_force].
        force: f64,
        /// Ramp rate, normalised force per second.
        #[serde(default)]
        rate_per_s: Option<f64>,
    },
    /// Run a profile (a cardiac profile while one runs: retuned from the next beat).
    Profile {
        /// The profile.
        profile: ProfileSpec,
    },
    /// Stop stimulation: reference to zero at once, driver disarmed.
    Stop,
    /// Arm the driver (also clears a fault once its cause is gone); the reference starts
    /// at zero.
    Arm,
    /// Switch the outer loop on or off.
    OuterLoop {
        /// On or off.
        enabled: bool,
    },
}

impl Command {
    /// The command's name.
    pub fn name(&self) -> &'static str {
        match self {
            Command::Status => "status",
            Command::Set { .. } => "set",
            Command::Profile { .. } => "profile",
            Command::Stop => "stop",
            Command::Arm => "arm",
            Command::OuterLoop { .. } => "outer_loop",
        }
    }
}

/// A request line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Request {
    /// Protocol version, must be [`VERSION`].
    pub v: u32,
    /// Client's request id, echoed in the response.
    #[serde(default)]
    pub id: u64,
    /// What to do.
    pub command: Command,
}

/// A response line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Response {
    /// Protocol version of the daemon.
    pub v: u32,
    /// The request's id (0 when the request could not be read).
    pub id: u64,
    /// Whether the command was carried out.
    pub ok: bool,
    /// What was done (when ok).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub message: Option<String>,
    /// Why nothing was done (when not ok).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The state after the command (for `status`, and after every accepted command).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub status: Option<Status>,
}

impl Response {
    /// A success.
    pub fn ok(id: u64, message: impl Into<String>, status: Option<Status>) -> Self {
        Self {
            v: VERSION,
            id,
            ok: true,
            message: Some(message.into()),
            error: None,
            status,
        }
    }

    /// A refusal.
    pub fn error(id: u64, error: impl Into<String>) -> Self {
        Self {
            v: VERSION,
            id,
            ok: false,
            message: None,
            error: Some(error.into()),
            status: None,
        }
    }

    /// The response as one line (no newline).
    pub fn to_line(&self) -> String {
        serde_json::to_string(self).unwrap_or_else(|e| {
            format!(
                r#"{{"v":{VERSION},"id":{},"ok":false,"error":"cannot encode the response: {e}"}}"#,
                self.id
            )
        })
    }
}

/// Why a request line was refused.
#[derive(Debug, thiserror::Error)]
pub enum ProtocolError {
    /// Longer than [`MAX_LINE`].
    #[error("request longer than {MAX_LINE} bytes")]
    TooLong,
    /// Not UTF-8.
    #[error("request is not UTF-8 text (invalid byte at offset {0})")]
    NotUtf8(usize),
    /// Empty line.
    #[error("empty request")]
    Empty,
    /// Not a valid request object (serde's message names the field).
    #[error("malformed request: {0}")]
    Malformed(#[source] serde_json::Error),
    /// No integer `v` field.
    #[error("malformed request: missing or non-integer field `v` (protocol version)")]
    NoVersion,
    /// Another protocol version.
    #[error("protocol version {found} is not supported (this supervisor speaks version {VERSION})")]
    Version {
        /// The client's version.
        found: u32,
    },
}

/// Parses one request line (without its newline). Never panics.
pub fn parse_request(line: &[u8]) -> Result<Request, ProtocolError> {
    if line.len() > MAX_LINE {
        return Err(ProtocolError::TooLong);
    }
    let text = std::str::from_utf8(line).map_err(|e| ProtocolError::NotUtf8(e.valid_up_to()))?;
    let text = text.trim();
    if text.is_empty() {
        return Err(ProtocolError::Empty);
    }
    // Check the version first, so that a newer client gets the version error rather than
    // a complaint about a field it added.
    let value: serde_json::Value = serde_json::from_str(text).map_err(ProtocolError::Malformed)?;
    match value.get("v").and_then(serde_json::Value::as_u64) {
        Some(v) if v == u64::from(VERSION) => {}
        Some(v) => {
            return Err(ProtocolError::Version {
                found: u32::try_from(v).unwrap_or(u32::MAX),
            });
        }
        None => {
            return Err(ProtocolError::NoVersion);
        }
    }
    serde_json::from_value(value).map_err(ProtocolError::Malformed)
}

/// Parses a response line. Never panics.
pub fn parse_response(line: &[u8]) -> Result<Response, ProtocolError> {
    if line.len() > 16 * MAX_LINE {
        return Err(ProtocolError::TooLong);
    }
    let text = std::str::from_utf8(line).map_err(|e| ProtocolError::NotUtf8(e.valid_up_to()))?;
    serde_json::from_str(text.trim()).map_err(ProtocolError::Malformed)
}

/// Health of one watched process, as reported.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProcessStatus {
    /// `rt-core`, `stim-driver` or `sim-muscle`.
    pub name: String,
    /// `ok`, `waiting` (not seen yet), `stalled`, `dead`, `exited` or `fault`.
    pub state: ProcessState,
    /// Process id, if known (iceoryx2 node details).
    #[serde(default)]
    pub pid: Option<u32>,
    /// Age of its last message, ms.
    #[serde(default)]
    pub last_message_age_ms: Option<f64>,
    /// Details (the reason when not ok).
    #[serde(default)]
    pub detail: String,
}

/// A watched process's state, from the typed cause of its fault (JSON: the lowercase name).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum ProcessState {
    /// Not heard from yet.
    #[default]
    Waiting,
    /// Heard from within its timeout, no fault.
    Ok,
    /// Silent beyond its timeout while alive (or stopped by a signal).
    Stalled,
    /// Gone, a zombie, or its iceoryx2 node dead.
    Dead,
    /// Ended: its node is gone after a final message.
    Exited,
    /// Any other fault (EMCY, device fault, invalid message, ...).
    Fault,
}

impl ProcessState {
    /// The lowercase name (as in the JSON).
    pub fn name(self) -> &'static str {
        match self {
            ProcessState::Waiting => "waiting",
            ProcessState::Ok => "ok",
            ProcessState::Stalled => "stalled",
            ProcessState::Dead => "dead",
            ProcessState::Exited => "exited",
            ProcessState::Fault => "fault",
        }
    }
}

impl std::fmt::Display for ProcessState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The daemon's state, as `supervisor status` shows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Status {
    /// `disarmed`, `armed` or `fault`.
    pub state: String,
    /// The fault that stopped stimulation, while in `fault`, in words.
    #[serde(default)]
    pub fault: Option<String>,
    /// The same fault typed (`{"source": "process", "process": "RtCore", "pid": 7,
    /// "cause": {"kind": "died"}}`, `{"source": "recording"}`, `{"source": "self_stall"}`):
    /// what a program acts on instead of matching the words.
    #[serde(default)]
    pub fault_cause: Option<FaultCause>,
    /// Seconds since start.
    pub uptime_s: f64,
    /// Last published reference: force.
    pub reference: f64,
    /// Last published reference: ramp rate, /s.
    pub reference_rate_per_s: f64,
    /// Last published reference: stop flag.
    pub reference_stop: bool,
    /// References published.
    pub references_published: u64,
    /// The running profile, if any.
    #[serde(default)]
    pub profile: Option<String>,
    /// Running beat (cardiac).
    #[serde(default)]
    pub beat: Option<u64>,
    /// Outer loop on.
    pub outer_loop: bool,
    /// Outer-loop correction, normalised force.
    pub outer_loop_correction: f64,
    /// Last measured contraction (plateau mean), normalised force.
    #[serde(default)]
    pub last_contraction: Option<f64>,
    /// Watched processes.
    #[serde(default)]
    pub processes: Vec<ProcessStatus>,
    /// Driver state (DriverStatus), if heard.
    #[serde(default)]
    pub driver_state: Option<String>,
    /// Stimulator state (DriverStatus), if heard.
    #[serde(default)]
    pub stimulator_state: Option<String>,
    /// Recording directory of the current run, if recording.
    #[serde(default)]
    pub recording: Option<String>,
    /// The newest order to the driver and its acknowledgement (absent before the first).
    #[serde(default)]
    pub driver_order: Option<DriverOrderStatus>,
    /// Recent events, newest last.
    #[serde(default)]
    pub events: Vec<String>,
}

/// The newest order to the driver and where it stands: what `supervisor stop` and
/// `supervisor arm` wait for.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DriverOrderStatus {
    /// `arm`, `disarm` or `safe_stop`.
    pub order: String,
    /// Its identity (the DriverCommand sequence number of its first send): a newer order
    /// has a larger one.
    pub id: u64,
    /// `pending`, `confirmed`, `refused`, `unacknowledged` or `unwatched` (the driver's
    /// acknowledgements are not watched: unknown).
    pub outcome: String,
    /// Why it was refused.
    #[serde(default)]
    pub reason: Option<String>,
}

impl DriverOrderStatus {
    /// A stop order (`disarm` or `safe_stop`).
    pub fn is_stop(&self) -> bool {
        self.order == "disarm" || self.order == "safe_stop"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_errors() {
        let r = Request {
            v: VERSION,
            id: 7,
            command: Command::Set {
                force: 0.4,
                rate_per_s: Some(5.0),
            },
        };
        let line = serde_json::to_string(&r).unwrap();
        assert_eq!(
            line,
            r#"{"v":1,"id":7,"command":{"kind":"set","force":0.4,"rate_per_s":5.0}}"#
        );
        assert_eq!(parse_request(line.as_bytes()).unwrap(), r);
        assert!(matches!(
            parse_request(br#"{"v":2,"command":{"kind":"stop"}}"#).unwrap_err(),
            ProtocolError::Version { found: 2 }
        ));
        let e =
            parse_request(br#"{"v":1,"command":{"kind":"set","force":0.4,"x":1}}"#).unwrap_err();
        assert!(matches!(e, ProtocolError::Malformed(_)), "{e}");
        assert!(e.to_string().contains("unknown field `x`"), "{e}");
        let e = parse_request(br#"{"v":1,"command":{"kind":"launch"}}"#).unwrap_err();
        assert!(e.to_string().contains("unknown variant `launch`"), "{e}");
        assert!(matches!(
            parse_request(b"  ").unwrap_err(),
            ProtocolError::Empty
        ));
        assert!(matches!(
            parse_request(&[b'{', 0xff]).unwrap_err(),
            ProtocolError::NotUtf8(1)
        ));
        // NaN is not JSON: a client cannot even send it.
        assert!(parse_request(br#"{"v":1,"command":{"kind":"set","force":NaN}}"#).is_err());
        let resp = Response::error(3, "no");
        assert_eq!(parse_response(resp.to_line().as_bytes()).unwrap(), resp);
    }
}
