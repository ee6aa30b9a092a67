//! The RehaStim 2's value ranges (§4.3 and the device's data sheet): what a device
//! answers with [`crate::AckResult::ParameterError`], and what a host must not send.

use crate::message::{ChannelListInit, ChannelPulse, SinglePulse};

/// Stimulation channels (channel numbers 1..=8 in channel lists, 0..=7 in SinglePulse).
pub const CHANNELS: u8 = 8;
/// Highest current, mA (the device's output range is 0..=126 mA in 2 mA steps).
pub const MAX_CURRENT_MA: u8 = 126;
/// Longest pulse width, us.
pub const MAX_PULSE_WIDTH_US: u16 = 500;
/// Shortest pulse width the device generates, us: a width of 1..=19 us is raised to 20 us;
/// 0 fires no pulse.
pub const MIN_PULSE_WIDTH_US: u16 = 20;
/// Highest low-frequency factor.
pub const MAX_LOW_FREQUENCY_FACTOR: u8 = 7;
/// Shortest main stimulation interval the device accepts, as its code (8 ms).
pub const MIN_MAIN_INTERVAL_CODE: u16 = 14;
/// Longest main stimulation interval, as its code (1025 ms).
pub const MAX_MAIN_INTERVAL_CODE: u16 = 2048;

/// Whether a pulse of `pulse_width_us` and `current_ma` is within the device's range.
pub const fn pulse_in_range(pulse_width_us: u16, current_ma: u8) -> bool {
    pulse_width_us <= MAX_PULSE_WIDTH_US && current_ma <= MAX_CURRENT_MA
}

/// The width the device actually generates for a requested `pulse_width_us` (in range):
/// 0 stays 0 (no pulse), 1..=19 becomes 20.
pub const fn effective_width_us(pulse_width_us: u16) -> u16 {
    if pulse_width_us == 0 || pulse_width_us >= MIN_PULSE_WIDTH_US {
        pulse_width_us
    } else {
        MIN_PULSE_WIDTH_US
    }
}

impl SinglePulse {
    /// Whether the device accepts this pulse.
    pub const fn in_range(&self) -> bool {
        self.channel < CHANNELS && pulse_in_range(self.pulse_width_us, self.current_ma)
    }
}

impl ChannelPulse {
    /// Whether the device accepts this entry.
    pub const fn in_range(&self) -> bool {
        pulse_in_range(self.pulse_width_us, self.current_ma)
    }
}

impl ChannelListInit {
    /// Whether the device accepts this initialisation: a channel active, low-frequency
    /// channels among the active ones, factor and intervals in range.
    pub const fn in_range(&self) -> bool {
        self.active_channels != 0
            && self.low_frequency_channels & !self.active_channels == 0
            && self.low_frequency_factor <= MAX_LOW_FREQUENCY_FACTOR
            && self.main_interval_code >= MIN_MAIN_INTERVAL_CODE
            && self.main_interval_code <= MAX_MAIN_INTERVAL_CODE
    }
}
