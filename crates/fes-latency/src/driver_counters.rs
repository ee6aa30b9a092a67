//! [`DriverCounters`]: the stim-driver's counters that driver-latency writes in its JSON
//! summary and rt-latency reads back and sums over the rounds, declared once so the
//! writer and the reader cannot drift.

use serde::{Deserialize, Serialize};

/// The driver's counters of one driver-latency run (or, summed, of several).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct DriverCounters {
    /// StimTicks the driver received.
    pub ticks_received: u64,
    /// StimTicks missing (seq gaps).
    pub ticks_lost: u64,
    /// StimTicks refused as defective or late.
    pub ticks_refused: u64,
    /// PULSE frames written.
    pub pulses_sent: u64,
    /// Pulses refused by the driver's interlocks.
    pub pulses_rejected: u64,
    /// Pulse decisions while not armed (before the Arm, after a trip).
    pub pulses_not_armed: u64,
    /// Pulses the virtual stimulator applied.
    pub stimulator_pulses: u64,
    /// Frame writes that failed.
    pub can_tx_errors: u64,
    /// Trips into the safe state.
    pub trips: u64,
    /// Of which watchdog trips.
    pub watchdog_trips: u64,
    /// Times the supervisor stand-in armed the driver (1 + re-arms after trips).
    pub arms: u64,
    /// Heap allocations on the forward thread's hot path (0 is the requirement).
    pub hot_path_allocations: u64,
}

impl DriverCounters {
    /// Adds `other`'s counts to these.
    pub fn add(&mut self, other: &DriverCounters) {
        self.ticks_received += other.ticks_received;
        self.ticks_lost += other.ticks_lost;
        self.ticks_refused += other.ticks_refused;
        self.pulses_sent += other.pulses_sent;
        self.pulses_rejected += other.pulses_rejected;
        self.pulses_not_armed += other.pulses_not_armed;
        self.stimulator_pulses += other.stimulator_pulses;
        self.can_tx_errors += other.can_tx_errors;
        self.trips += other.trips;
        self.watchdog_trips += other.watchdog_trips;
        self.arms += other.arms;
        self.hot_path_allocations += other.hot_path_allocations;
    }
}
