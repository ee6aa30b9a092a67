//! The random pattern method (thesis 6.2, Figs. 6.1-6.2): FTIpP of many patterns with
//! random inter-pulse intervals against their average stimulation frequency (eq. 6.5-6.6),
//! and the best and worst patterns.
//!
//! The patterns come from the caller (the supervisor draws them with sim-muscle's thesis
//! protocol, 5.1, so the method sees the same kind of trains as the identification data).

use rayon::prelude::*;

use super::{Evaluator, ForceResponse, OspError, PatternResult, average_frequency};

/// One random pattern's result.
#[derive(Debug, Clone, PartialEq)]
pub struct RandomPattern {
    /// FTI, FTIpP, peak.
    pub result: PatternResult,
    /// Average stimulation frequency, eq. (6.6), Hz; `None` for a single pulse.
    pub average_frequency_hz: Option<f64>,
}

/// Evaluates every pattern (in parallel); `progress` is called once per pattern done.
/// Results are in the order of `patterns`.
pub fn random_method<R: ForceResponse + ?Sized>(
    ev: &Evaluator<'_, R>,
    patterns: &[Vec<usize>],
    progress: &(dyn Fn() + Sync),
) -> Result<Vec<RandomPattern>, OspError> {
    if patterns.is_empty() {
        return Err(OspError::Settings {
            method: "the random pattern method",
            setting: "patterns",
            value: patterns.len(),
            min: 1,
            max: None,
        });
    }
    let ts = ev.ts();
    patterns
        .par_iter()
        .map(|p| {
            let result = ev.evaluate(p)?;
            progress();
            Ok(RandomPattern {
                average_frequency_hz: average_frequency(p, ts),
                result,
            })
        })
        .collect()
}

/// Indices of the `n` best (highest FTIpP first) and `n` worst (lowest first) patterns
/// among those with at least two pulses (a single pulse has FTIpP 1 by definition and no
/// frequency).
pub fn best_and_worst(results: &[RandomPattern], n: usize) -> (Vec<usize>, Vec<usize>) {
    let mut idx: Vec<usize> = (0..results.len())
        .filter(|&i| results[i].average_frequency_hz.is_some())
        .collect();
    idx.sort_by(|&a, &b| results[b].result.ftipp.total_cmp(&results[a].result.ftipp));
    let best = idx.iter().take(n).copied().collect();
    let worst = idx.iter().rev().take(n).copied().collect();
    (best, worst)
}
