//! The real-time side shared by the processes of the stimulation chain: the iceoryx2
//! message contracts ([`msg`]) and the real-time plumbing ([`rt`]). It links neither the
//! numerics nor plotting, so the stimulator driver that depends on it does not either.
#![deny(clippy::missing_safety_doc)]

mod code_enum;
pub mod msg;
pub mod rt;
