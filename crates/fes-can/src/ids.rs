//! Node ids and COB-IDs (CANopen-style identifier layout).
//!
//! A COB-ID is a function code plus a node id, as in CANopen's predefined connection
//! set: EMCY 0x080, PULSE 0x100, FORCE 0x180, STATUS 0x280, CONFIG 0x300 (each + the
//! stimulator's node id), CONFIG_APPLIED 0x380 + stimulator, heartbeat 0x700 + the sender's node id, NMT fixed at 0x000.

use crate::desc::MessageDesc;
use crate::table::MESSAGES;

/// The two nodes on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Role {
    /// The controller side (stim-driver).
    Host,
    /// The stimulator.
    Stim,
}

impl Role {
    /// The node's name in the DBC (`BU_`).
    pub const fn dbc_name(self) -> &'static str {
        match self {
            Role::Host => "HOST",
            Role::Stim => "STIM",
        }
    }
}

/// Every message of the protocol.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MessageKind {
    /// NMT node control, host -> stimulator.
    Nmt,
    /// Emergency, stimulator -> host.
    Emcy,
    /// One stimulation pulse, host -> stimulator.
    Pulse,
    /// Force sample, stimulator -> host, every 1 ms.
    Force,
    /// Stimulator status, every 10 ms.
    Status,
    /// Run limits (multiplexed, three pages), host -> stimulator, pre-operational only.
    Config,
    /// The limits the stimulator applied (CONFIG's layout), stimulator -> host, once per
    /// page after a complete CONFIG: the host compares them with what it sent.
    ConfigApplied,
    /// Host heartbeat.
    HostHeartbeat,
    /// Stimulator heartbeat (and boot-up message).
    StimHeartbeat,
}

impl MessageKind {
    /// Every message kind, in COB-ID order for the default nodes.
    pub const ALL: [MessageKind; 9] = [
        MessageKind::Nmt,
        MessageKind::Emcy,
        MessageKind::Pulse,
        MessageKind::Force,
        MessageKind::Status,
        MessageKind::Config,
        MessageKind::ConfigApplied,
        MessageKind::HostHeartbeat,
        MessageKind::StimHeartbeat,
    ];

    /// The message's descriptor.
    pub const fn desc(self) -> &'static MessageDesc {
        &MESSAGES[self as usize]
    }

    /// The DBC message name.
    pub const fn name(self) -> &'static str {
        self.desc().name
    }
}

/// A CANopen node id was outside 1..=127 or the two nodes collide.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum NodeError {
    /// Node ids are 1..=127 in CANopen (0 means "all nodes" in NMT).
    #[error("node id {0:#04x} outside 1..=0x7f")]
    OutOfRange(u8),
    /// Host and stimulator must have different node ids (their heartbeats would clash).
    #[error("host and stimulator both use node id {0:#04x}")]
    Same(u8),
    /// The text is not a number of 0..=255 (decimal or `0x` hexadecimal).
    #[error("not a node id (decimal 1..=127 or hexadecimal 0x01..=0x7f)")]
    NotANumber,
}

/// A node id given as decimal or `0x` hexadecimal text (a command-line option), 1..=127.
pub fn parse_node_id(s: &str) -> Result<u8, NodeError> {
    let v = match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(hex) => u8::from_str_radix(hex, 16),
        None => s.parse::<u8>(),
    }
    .map_err(|_| NodeError::NotANumber)?;
    if (1..=0x7F).contains(&v) {
        Ok(v)
    } else {
        Err(NodeError::OutOfRange(v))
    }
}

/// The node ids of the host and the stimulator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Nodes {
    host: u8,
    stim: u8,
}

impl Default for Nodes {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl Nodes {
    /// Host node 0x01, stimulator node 0x10 (the ids in `fes.dbc`).
    pub const DEFAULT: Nodes = Nodes {
        host: 0x01,
        stim: 0x10,
    };

    /// Validated node ids.
    pub const fn new(host: u8, stim: u8) -> Result<Self, NodeError> {
        if host == 0 || host > 0x7F {
            return Err(NodeError::OutOfRange(host));
        }
        if stim == 0 || stim > 0x7F {
            return Err(NodeError::OutOfRange(stim));
        }
        if host == stim {
            return Err(NodeError::Same(host));
        }
        Ok(Self { host, stim })
    }

    /// The host's node id.
    pub const fn host(&self) -> u8 {
        self.host
    }

    /// The stimulator's node id.
    pub const fn stim(&self) -> u8 {
        self.stim
    }

    /// The node id of `role`.
    pub const fn node(&self, role: Role) -> u8 {
        match role {
            Role::Host => self.host,
            Role::Stim => self.stim,
        }
    }

    /// The COB-ID of `kind` with these nodes.
    pub const fn id_of(&self, kind: MessageKind) -> u16 {
        let d = kind.desc();
        match d.id_node {
            Some(role) => d.function_code + self.node(role) as u16,
            None => d.function_code,
        }
    }

    /// The message kind a received identifier carries, if it belongs to this protocol.
    /// Identifiers above 0x7FF (extended frames) never do.
    pub fn kind_of(&self, id: u32) -> Option<MessageKind> {
        if id > 0x7FF {
            return None;
        }
        MessageKind::ALL
            .into_iter()
            .find(|&k| u32::from(self.id_of(k)) == id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn node_ids_parse_in_decimal_and_hex_within_canopen_range() {
        assert_eq!(parse_node_id("16"), Ok(16));
        assert_eq!(parse_node_id("0x10"), Ok(16));
        assert_eq!(parse_node_id("0X7f"), Ok(127));
        assert_eq!(parse_node_id("0"), Err(NodeError::OutOfRange(0)));
        assert_eq!(parse_node_id("0x80"), Err(NodeError::OutOfRange(0x80)));
        for bad in ["", "0x", "ten", "256", "-1", "0x1g"] {
            assert_eq!(parse_node_id(bad), Err(NodeError::NotANumber), "{bad:?}");
        }
    }

    #[test]
    fn default_ids_follow_the_canopen_layout() {
        let n = Nodes::DEFAULT;
        assert_eq!(n.id_of(MessageKind::Nmt), 0x000);
        assert_eq!(n.id_of(MessageKind::Emcy), 0x090);
        assert_eq!(n.id_of(MessageKind::Pulse), 0x110);
        assert_eq!(n.id_of(MessageKind::Force), 0x190);
        assert_eq!(n.id_of(MessageKind::Status), 0x290);
        assert_eq!(n.id_of(MessageKind::Config), 0x310);
        assert_eq!(n.id_of(MessageKind::ConfigApplied), 0x390);
        assert_eq!(n.id_of(MessageKind::HostHeartbeat), 0x701);
        assert_eq!(n.id_of(MessageKind::StimHeartbeat), 0x710);
    }

    #[test]
    fn kind_of_inverts_id_of_for_any_nodes() {
        for (h, s) in [(0x01, 0x10), (0x7F, 0x01), (0x22, 0x23)] {
            let n = Nodes::new(h, s).unwrap();
            for k in MessageKind::ALL {
                assert_eq!(n.kind_of(u32::from(n.id_of(k))), Some(k), "{k:?} {h} {s}");
            }
        }
        assert_eq!(Nodes::DEFAULT.kind_of(0x111), None);
        assert_eq!(Nodes::DEFAULT.kind_of(0x8000_0110), None);
    }

    #[test]
    fn node_ids_are_validated() {
        assert_eq!(Nodes::new(0, 0x10), Err(NodeError::OutOfRange(0)));
        assert_eq!(Nodes::new(1, 0x80), Err(NodeError::OutOfRange(0x80)));
        assert_eq!(Nodes::new(5, 5), Err(NodeError::Same(5)));
    }

    #[test]
    fn descriptor_table_is_indexed_by_kind() {
        for k in MessageKind::ALL {
            assert_eq!(k.desc().kind, k);
        }
    }
}
