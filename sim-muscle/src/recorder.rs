//! The data-set recorder: runs a plant through a protocol's records, each from rest,
//! removes the offset, normalises the force to [0, 1] and builds an
//! `fes_dataset::DataSet`.

use std::collections::BTreeMap;

use fes_dataset::{DataSet, FORCE_SLACK, Header, Record, Split};

use crate::plant::{MusclePlant, Pulse};
use crate::protocol::{ProtocolConfig, ProtocolError, RecordPlan};
use crate::simulate::simulate;

/// Why recording failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RecordError {
    /// The protocol is invalid.
    #[error(transparent)]
    Protocol(#[from] ProtocolError),
    /// The plant's sample period differs from the protocol's.
    #[error("the muscle samples every {plant_ms} ms but the protocol every {protocol_ms} ms")]
    SamplePeriod {
        /// Plant's period, ms.
        plant_ms: f64,
        /// Protocol's period, ms.
        protocol_ms: f64,
    },
    /// The force never rose above the offset, so it cannot be normalised.
    #[error("the recorded force never rises above its offset ({offset_n} N); nothing to normalise")]
    NoForce {
        /// Estimated offset, N.
        offset_n: f64,
    },
    /// The scale to normalise by is not a positive force.
    #[error("the force scale {0} N must be finite and > 0")]
    Scale(f64),
    /// Every training or every test record exceeds the scale given.
    #[error(
        "with scale {scale_n} N every training or every test record peaks above the reader's bound (this recording peaks at {peak} N)"
    )]
    AllAboveScale {
        /// The scale given, N.
        scale_n: f64,
        /// This recording's offset-free peak, N.
        peak: f64,
    },
    /// The muscle produced a non-finite force.
    #[error("record {record}: the muscle produced a non-finite force at sample {sample}")]
    NotFinite {
        /// Record index.
        record: usize,
        /// Sample index.
        sample: usize,
    },
}

/// What the data set records about its origin (stored in `dataset.json`).
#[derive(Debug, Clone, PartialEq)]
pub struct Origin {
    /// Producer, e.g. `sim-muscle 0.1.0`.
    pub source: String,
    /// Preset name, if the muscle is a preset.
    pub preset: Option<String>,
    /// Model parameters by name (SI units).
    pub parameters: BTreeMap<String, f64>,
    /// Seed of the protocol and the noise.
    pub seed: u64,
    /// Measurement settings.
    pub noise: serde_json::Value,
}

/// Raw (newton) records before normalisation.
#[derive(Debug, Clone, PartialEq)]
pub struct RawRecords {
    /// Plans, one per record.
    pub plans: Vec<RecordPlan>,
    /// Measured force, N, one vector per record.
    pub force_n: Vec<Vec<f64>>,
}

/// Runs every plan on `plant`: a rest of `protocol.rest_s` before each record except the
/// first (the plant is reset first), supramaximal pulses.
pub fn run_records(
    plant: &mut dyn MusclePlant,
    protocol: &ProtocolConfig,
    plans: Vec<RecordPlan>,
) -> Result<RawRecords, RecordError> {
    let plant_ms = plant.ts() * 1e3;
    if (plant_ms - protocol.ts_ms).abs() > 1e-9 * protocol.ts_ms {
        return Err(RecordError::SamplePeriod {
            plant_ms,
            protocol_ms: protocol.ts_ms,
        });
    }
    plant.reset();
    let mut force_n = Vec::with_capacity(plans.len());
    for (record, plan) in plans.iter().enumerate() {
        if record > 0 {
            plant.rest(protocol.rest_s);
        }
        let f = simulate(plant, &plan.pulses, Pulse::SUPRAMAXIMAL);
        if let Some(sample) = f.iter().position(|x| !x.is_finite()) {
            return Err(RecordError::NotFinite { record, sample });
        }
        force_n.push(f);
    }
    Ok(RawRecords { plans, force_n })
}

/// The offset: mean force over every sample up to and including each record's first
/// pulse (the muscle is at rest there whatever the electromechanical delay).
pub fn estimate_offset(raw: &RawRecords) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for (plan, f) in raw.plans.iter().zip(&raw.force_n) {
        let first = plan
            .pulses
            .iter()
            .position(|&p| p)
            .unwrap_or(f.len().saturating_sub(1));
        for x in f.iter().take(first + 1) {
            sum += x;
            n += 1;
        }
    }
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// How a recording's force is normalised.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Normalise {
    /// By the largest offset-free sample of this recording (thesis 5.1: the maximum is 1).
    Peak,
    /// By a given force, N: another data set's `scale_n`, so that two recordings of one
    /// muscle share their units (a model's levels are fractions of its data's scale, so a
    /// richer protocol that reaches a higher peak would otherwise shift every level). A
    /// record whose force exceeds `1 + FORCE_SLACK` of it (the data-set reader's bound) is
    /// left out, the others keeping their train or test membership.
    Scale(f64),
}

/// Normalises the raw records into a data set: offset removed, divided by the largest
/// offset-free sample (so the maximum is exactly 1; the noise floor straddles 0), first
/// `protocol.train_records` records train.
pub fn build_dataset(
    raw: RawRecords,
    protocol: &ProtocolConfig,
    origin: Origin,
) -> Result<DataSet, RecordError> {
    build_normalised(raw, protocol, origin, Normalise::Peak)
}

/// [`build_dataset`] with the scale chosen by `norm`.
pub fn build_normalised(
    raw: RawRecords,
    protocol: &ProtocolConfig,
    origin: Origin,
    norm: Normalise,
) -> Result<DataSet, RecordError> {
    let offset_n = estimate_offset(&raw);
    let peak = raw
        .force_n
        .iter()
        .flatten()
        .map(|x| x - offset_n)
        .fold(f64::NEG_INFINITY, f64::max);
    if peak.is_nan() || peak <= 0.0 {
        return Err(RecordError::NoForce { offset_n });
    }
    let scale_n = match norm {
        Normalise::Peak => peak,
        Normalise::Scale(s) if s.is_finite() && s > 0.0 => s,
        Normalise::Scale(s) => return Err(RecordError::Scale(s)),
    };
    let ts_s = protocol.ts_ms * 1e-3;
    let n = raw.plans.len();
    let first = Split::first(protocol.train_records, n);
    let mut split = Split {
        train: Vec::new(),
        test: Vec::new(),
    };
    let mut records = Vec::with_capacity(n);
    for (i, (plan, f)) in raw.plans.into_iter().zip(raw.force_n).enumerate() {
        let force: Vec<f64> = f.iter().map(|x| (x - offset_n) / scale_n).collect();
        if force.iter().any(|&x| x > 1.0 + FORCE_SLACK) {
            continue;
        }
        let k = records.len();
        if first.train.contains(&i) {
            split.train.push(k);
        } else if first.test.contains(&i) {
            split.test.push(k);
        }
        records.push(Record::uniform(
            format!("record_{k:03}.csv"),
            plan.kind,
            ts_s,
            plan.pulses,
            force,
        ));
    }
    if split.train.is_empty() || split.test.is_empty() {
        return Err(RecordError::AllAboveScale { scale_n, peak });
    }
    let protocol_json = serde_json::to_value(protocol).unwrap_or(serde_json::Value::Null);
    Ok(DataSet {
        header: Header {
            source: origin.source,
            preset: origin.preset,
            parameters: origin.parameters,
            seed: Some(origin.seed),
            noise: origin.noise,
            protocol: protocol_json,
            scale_n,
            offset_n,
            ts_s,
            split,
        },
        records,
    })
}

/// Plans the protocol with `origin.seed`, runs it on `plant` and builds the data set.
pub fn record(
    plant: &mut dyn MusclePlant,
    protocol: &ProtocolConfig,
    origin: Origin,
) -> Result<DataSet, RecordError> {
    record_normalised(plant, protocol, origin, Normalise::Peak)
}

/// [`record`] with the scale chosen by `norm`.
pub fn record_normalised(
    plant: &mut dyn MusclePlant,
    protocol: &ProtocolConfig,
    origin: Origin,
    norm: Normalise,
) -> Result<DataSet, RecordError> {
    let plans = protocol.plan(origin.seed)?;
    let raw = run_records(plant, protocol, plans)?;
    build_normalised(raw, protocol, origin, norm)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::muscle::{Muscle, MuscleConfig};
    use crate::preset::Preset;
    use crate::sensor::{ForceSensor, Measured, SensorConfig};

    fn origin() -> Origin {
        Origin {
            source: "test".into(),
            preset: None,
            parameters: BTreeMap::new(),
            seed: 5,
            noise: serde_json::Value::Null,
        }
    }

    /// A known sensor offset is recovered from the rest samples within 4 standard errors
    /// (noise 1 N); the normalised maximum is exactly 1; the split is 30 / rest.
    #[test]
    fn offset_recovered_and_scale_normalises() {
        let protocol = ProtocolConfig::thesis(Preset::Fast);
        let sensor = SensorConfig {
            offset_n: 5.0,
            noise_std_n: 1.0,
            lowpass_tau_s: 0.0,
            seed: 5,
        };
        let cfg = MuscleConfig::preset(Preset::Fast);
        let mut plant = Measured::new(
            Muscle::new(cfg).expect("valid"),
            ForceSensor::new(sensor, cfg.ts_s).expect("valid"),
        );
        let plans = protocol.plan(5).expect("plan");
        let raw = run_records(&mut plant, &protocol, plans).expect("run");
        let rest_samples = protocol.records * (protocol.train_start_ms as usize + 1);
        let offset = estimate_offset(&raw);
        assert!(
            (offset - 5.0).abs() < 4.0 / (rest_samples as f64).sqrt(),
            "offset {offset}"
        );
        let ds = build_dataset(raw, &protocol, origin()).expect("build");
        let max = ds
            .records
            .iter()
            .flat_map(|r| r.force.iter().copied())
            .fold(f64::MIN, f64::max);
        assert_eq!(max, 1.0);
        assert_eq!(ds.header.split.train.len(), 30);
        assert_eq!(ds.header.split.test.len(), 30);
        assert_eq!(ds.header.offset_n, offset);
    }

    /// Normalised by a given scale: a scale of half the peak leaves out exactly the records
    /// that exceed 1.1 of it, keeps the others' train or test membership and their force
    /// (scaled by 2 against the peak's normalisation); a scale that is not a positive force
    /// is refused.
    #[test]
    fn a_given_scale_leaves_out_the_records_above_the_bound() {
        let protocol = ProtocolConfig::thesis(Preset::Fast);
        let cfg = MuscleConfig::preset(Preset::Fast);
        let raw = || {
            let mut plant = Muscle::new(cfg).expect("valid");
            run_records(&mut plant, &protocol, protocol.plan(5).expect("plan")).expect("run")
        };
        let by_peak = build_dataset(raw(), &protocol, origin()).expect("build");
        let half = by_peak.header.scale_n / 2.0;
        let scaled =
            build_normalised(raw(), &protocol, origin(), Normalise::Scale(half)).expect("build");
        let kept: Vec<usize> = (0..by_peak.records.len())
            .filter(|&i| by_peak.records[i].force.iter().all(|&x| 2.0 * x <= 1.1))
            .collect();
        assert!(!kept.is_empty() && kept.len() < by_peak.records.len());
        assert_eq!(scaled.records.len(), kept.len());
        assert_eq!(scaled.header.scale_n, half);
        for (k, &i) in kept.iter().enumerate() {
            let (a, b) = (&scaled.records[k], &by_peak.records[i]);
            assert_eq!(a.kind, b.kind);
            assert!(
                a.force
                    .iter()
                    .zip(&b.force)
                    .all(|(x, y)| (x - 2.0 * y).abs() < 1e-12)
            );
            assert_eq!(
                scaled.header.split.train.contains(&k),
                by_peak.header.split.train.contains(&i)
            );
        }
        for bad in [0.0, -1.0, f64::NAN] {
            assert!(matches!(
                build_normalised(raw(), &protocol, origin(), Normalise::Scale(bad)),
                Err(RecordError::Scale(_))
            ));
        }
    }

    /// A plant sampled at another period than the protocol is refused.
    #[test]
    fn sample_period_mismatch_is_refused() {
        let protocol = ProtocolConfig {
            ts_ms: 0.5,
            ..ProtocolConfig::thesis(Preset::Slow)
        };
        let mut plant = Muscle::new(MuscleConfig::preset(Preset::Slow)).expect("valid");
        let err = record(&mut plant, &protocol, origin()).expect_err("mismatch");
        assert!(matches!(err, RecordError::SamplePeriod { .. }), "{err}");
    }
}
