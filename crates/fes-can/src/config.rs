//! The stimulator's run limits and their transport in the two CONFIG pages.

use crate::desc::SignalDesc;
use crate::message::{Config, ConfigPage};
use crate::table::config as sig;

/// Run limits of a stimulator (one complete configuration).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StimLimits {
    /// Amplitude ceiling in 0.1 mA steps.
    pub max_amplitude_100ua: u16,
    /// Width ceiling in us.
    pub max_width_us: u16,
    /// Minimum inter-pulse interval in ms.
    pub min_ipi_ms: u16,
    /// Most pulses in any window of `rate_window_ms`.
    pub max_pulses: u16,
    /// Rate window in ms.
    pub rate_window_ms: u16,
    /// Host heartbeat timeout in ms (operational state).
    pub watchdog_ms: u16,
    /// Charge-per-phase ceiling (amplitude x width of one phase) in 10 nC steps.
    pub max_charge_10nc: u16,
}

/// A limit outside the range the protocol can carry.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("{field} = {value} {unit} is outside {min}..={max} {unit}")]
pub struct LimitsError {
    /// The CONFIG signal name of the offending limit.
    pub field: &'static str,
    /// The value given (physical units).
    pub value: f64,
    /// Smallest allowed value.
    pub min: f64,
    /// Largest allowed value.
    pub max: f64,
    /// Unit.
    pub unit: &'static str,
}

impl Default for StimLimits {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl StimLimits {
    /// 100 mA, 500 us, 1 ms minimum IPI, at most 100 pulses per 1000 ms (a mean of
    /// 100 Hz), 100 ms watchdog (10 host heartbeats), 50 uC per phase (100 mA x 500 us:
    /// the stimulator's own ceiling adds nothing to its amplitude and width ceilings; a
    /// CONFIG makes it the prescription's).
    ///
    /// The minimum IPI is the stimulator's ceiling against a runaway host (1000 Hz), judged
    /// on the pulses' arrival: the pattern's own 2 ms minimum (the prescription's) is the driver's,
    /// on the generator's grid times, and a pulse the driver lets through may leave up to
    /// its `max_pulse_delay` late, so two legal pulses can arrive 1.5 ms apart. A 2 ms
    /// stimulator minimum refused such pairs now and then (a CI run of the kill test).
    pub const DEFAULT: StimLimits = StimLimits {
        max_amplitude_100ua: 1000,
        max_width_us: 500,
        min_ipi_ms: 1,
        max_pulses: 100,
        rate_window_ms: 1000,
        watchdog_ms: 100,
        max_charge_10nc: 5000,
    };

    /// Each limit with its CONFIG signal, in page order.
    fn fields(&self) -> [(&'static SignalDesc, u16); 7] {
        [
            (&sig::MAX_AMPLITUDE, self.max_amplitude_100ua),
            (&sig::MAX_WIDTH, self.max_width_us),
            (&sig::MIN_IPI, self.min_ipi_ms),
            (&sig::MAX_PULSES, self.max_pulses),
            (&sig::RATE_WINDOW, self.rate_window_ms),
            (&sig::WATCHDOG, self.watchdog_ms),
            (&sig::MAX_CHARGE, self.max_charge_10nc),
        ]
    }

    /// Checks every limit against its CONFIG signal's range (the same check `decode`
    /// applies to a received CONFIG frame).
    pub fn validate(&self) -> Result<(), LimitsError> {
        for (s, raw) in self.fields() {
            let raw = i64::from(raw);
            if raw < s.raw_min() || raw > s.raw_max() {
                return Err(LimitsError {
                    field: s.name,
                    value: s.physical(raw),
                    min: s.min,
                    max: s.max,
                    unit: s.unit,
                });
            }
        }
        Ok(())
    }

    /// Index (0-6, page order) of the first limit outside its range, for EMCY details.
    pub fn field_index(name: &str) -> Option<u16> {
        StimLimits::default()
            .fields()
            .iter()
            .position(|(s, _)| s.name == name)
            .and_then(|i| u16::try_from(i).ok())
    }

    /// The three CONFIG frames that carry these limits under `config_id` (1..=255); the
    /// stimulator answers with the same three pages as CONFIG_APPLIED.
    pub const fn to_pages(&self, config_id: u8) -> [Config; 3] {
        [
            Config {
                config_id,
                page: ConfigPage::OutputLimits {
                    max_amplitude_100ua: self.max_amplitude_100ua,
                    max_width_us: self.max_width_us,
                    min_ipi_ms: self.min_ipi_ms,
                },
            },
            Config {
                config_id,
                page: ConfigPage::RateAndWatchdog {
                    max_pulses: self.max_pulses,
                    rate_window_ms: self.rate_window_ms,
                    watchdog_ms: self.watchdog_ms,
                },
            },
            Config {
                config_id,
                page: ConfigPage::Charge {
                    max_charge_10nc: self.max_charge_10nc,
                },
            },
        ]
    }

    /// Charge-per-phase ceiling in nC.
    pub const fn max_charge_nc(&self) -> u32 {
        self.max_charge_10nc as u32 * 10
    }

    /// Amplitude ceiling in mA.
    pub fn max_amplitude_ma(&self) -> f64 {
        sig::MAX_AMPLITUDE.physical(i64::from(self.max_amplitude_100ua))
    }
}

/// Collects the three CONFIG (or CONFIG_APPLIED) pages of one configuration.
///
/// Pages are staged until all three carry the same `config_id`; the last page completes the
/// configuration. A page with another id replaces the staged one of its kind.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ConfigAssembler {
    output: Option<(u8, u16, u16, u16)>,
    rate: Option<(u8, u16, u16, u16)>,
    charge: Option<(u8, u16)>,
}

impl ConfigAssembler {
    /// An empty assembler.
    pub const fn new() -> Self {
        Self {
            output: None,
            rate: None,
            charge: None,
        }
    }

    /// Drops any staged page.
    pub fn clear(&mut self) {
        *self = Self::new();
    }

    /// True when a page is staged but the configuration is incomplete.
    pub const fn is_partial(&self) -> bool {
        self.output.is_some() || self.rate.is_some() || self.charge.is_some()
    }

    /// Stages `page`; returns the configuration id and limits when all pages match.
    pub fn push(&mut self, page: &Config) -> Option<(u8, StimLimits)> {
        match page.page {
            ConfigPage::OutputLimits {
                max_amplitude_100ua,
                max_width_us,
                min_ipi_ms,
            } => {
                self.output = Some((
                    page.config_id,
                    max_amplitude_100ua,
                    max_width_us,
                    min_ipi_ms,
                ));
            }
            ConfigPage::RateAndWatchdog {
                max_pulses,
                rate_window_ms,
                watchdog_ms,
            } => {
                self.rate = Some((page.config_id, max_pulses, rate_window_ms, watchdog_ms));
            }
            ConfigPage::Charge { max_charge_10nc } => {
                self.charge = Some((page.config_id, max_charge_10nc));
            }
        }
        match (self.output, self.rate, self.charge) {
            (Some((a, amp, width, ipi)), Some((b, pulses, window, wd)), Some((c, charge)))
                if a == b && b == c =>
            {
                self.clear();
                Some((
                    a,
                    StimLimits {
                        max_amplitude_100ua: amp,
                        max_width_us: width,
                        min_ipi_ms: ipi,
                        max_pulses: pulses,
                        rate_window_ms: window,
                        watchdog_ms: wd,
                        max_charge_10nc: charge,
                    },
                ))
            }
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid() {
        StimLimits::default().validate().unwrap();
    }

    #[test]
    fn validate_names_the_field() {
        let l = StimLimits {
            watchdog_ms: 10,
            ..StimLimits::default()
        };
        let e = l.validate().unwrap_err();
        assert_eq!(
            (e.field, e.value, e.min, e.max, e.unit),
            ("watchdog", 10.0, 20.0, 5000.0, "ms")
        );
        let l = StimLimits {
            max_amplitude_100ua: 1501,
            ..StimLimits::default()
        };
        assert_eq!(l.validate().unwrap_err().field, "max_amplitude");
        assert_eq!(StimLimits::field_index("watchdog"), Some(5));
        assert_eq!(StimLimits::field_index("max_charge"), Some(6));
        let l = StimLimits {
            max_charge_10nc: 15001,
            ..StimLimits::default()
        };
        assert_eq!(l.validate().unwrap_err().field, "max_charge");
    }

    #[test]
    fn pages_reassemble_in_either_order() {
        let l = StimLimits {
            max_amplitude_100ua: 321,
            min_ipi_ms: 5,
            ..StimLimits::default()
        };
        let [a, b, c] = l.to_pages(9);
        let mut asm = ConfigAssembler::new();
        assert_eq!(asm.push(&b), None);
        assert!(asm.is_partial());
        assert_eq!(asm.push(&c), None);
        assert_eq!(asm.push(&a), Some((9, l)));
        assert!(!asm.is_partial());
        assert_eq!(asm.push(&a), None);
        assert_eq!(asm.push(&c), None);
        assert_eq!(asm.push(&b), Some((9, l)));
    }

    #[test]
    fn mismatched_ids_do_not_combine() {
        let l = StimLimits::default();
        let [a, _, _] = l.to_pages(1);
        let [_, b, c] = l.to_pages(2);
        let mut asm = ConfigAssembler::new();
        assert_eq!(asm.push(&a), None);
        assert_eq!(asm.push(&b), None);
        assert_eq!(asm.push(&c), None);
        let [a2, _, _] = l.to_pages(2);
        assert_eq!(asm.push(&a2), Some((2, l)));
    }
}
