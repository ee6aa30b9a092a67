//! The iterative method (thesis 6.4, Fig. 6.4): start from the twitch; add pulses one at a
//! time, each at the IPI (swept over a range, thesis 2-100 ms in 1 ms steps) after the
//! previous pulse that maximises the FTIpP, and keep that IPI fixed from then on.

use rayon::prelude::*;

use super::{Evaluator, ForceResponse, OspError, PatternResult, ipi_range};

/// One stage: the pattern with `pulses` pulses, its last IPI swept.
#[derive(Debug, Clone, PartialEq)]
pub struct IterativeStage {
    /// Number of pulses in this stage's patterns (2, 3, ...).
    pub pulses: usize,
    /// The swept IPIs (samples) and their results.
    pub sweep: Vec<(usize, PatternResult)>,
    /// Index into `sweep` of the optimal IPI (largest FTIpP; the shortest IPI on ties).
    pub best: usize,
}

impl IterativeStage {
    /// The optimal IPI (samples) and its result.
    pub fn best(&self) -> &(usize, PatternResult) {
        &self.sweep[self.best]
    }
}

/// The result of the iterative method.
#[derive(Debug, Clone, PartialEq)]
pub struct Iterative {
    /// The twitch (stage 1).
    pub twitch: PatternResult,
    /// Stages 2..=N.
    pub stages: Vec<IterativeStage>,
}

impl Iterative {
    /// The optimal pattern found (pulse sample indices).
    pub fn pattern(&self) -> Vec<usize> {
        self.stages
            .last()
            .map_or_else(|| vec![0], |s| s.best().1.pulses.clone())
    }

    /// The optimal IPIs in order (samples).
    pub fn ipis(&self) -> Vec<usize> {
        self.stages.iter().map(|s| s.best().0).collect()
    }

    /// The stage (1 = the twitch) whose optimal pattern has the largest FTIpP, and that
    /// FTIpP.
    pub fn best_stage(&self) -> (usize, f64) {
        let mut best = (1, self.twitch.ftipp);
        for s in &self.stages {
            if s.best().1.ftipp > best.1 {
                best = (s.pulses, s.best().1.ftipp);
            }
        }
        best
    }
}

/// The iterative method up to `max_pulses` pulses, IPIs `ipi_min..=ipi_max` samples;
/// each stage's sweep runs in parallel; `progress` is called once per pattern done.
pub fn iterative_method<R: ForceResponse + ?Sized>(
    ev: &Evaluator<'_, R>,
    max_pulses: usize,
    ipi_min: usize,
    ipi_max: usize,
    progress: &(dyn Fn() + Sync),
) -> Result<Iterative, OspError> {
    if max_pulses == 0 {
        return Err(OspError::Settings {
            method: "the iterative method",
            setting: "max_pulses",
            value: max_pulses,
            min: 1,
            max: None,
        });
    }
    let ipis = ipi_range(ipi_min, ipi_max)?;
    let mut pattern = vec![0usize];
    let mut stages = Vec::with_capacity(max_pulses.saturating_sub(1));
    for pulses in 2..=max_pulses {
        let last = pattern[pattern.len() - 1];
        let sweep: Vec<(usize, PatternResult)> = ipis
            .par_iter()
            .map(|&ipi| {
                let mut p = pattern.clone();
                p.push(last + ipi);
                let r = ev.evaluate(&p);
                progress();
                r.map(|r| (ipi, r))
            })
            .collect::<Result<_, _>>()?;
        let mut best = 0;
        for (i, (_, r)) in sweep.iter().enumerate() {
            if r.ftipp > sweep[best].1.ftipp {
                best = i;
            }
        }
        pattern.push(last + sweep[best].0);
        stages.push(IterativeStage {
            pulses,
            sweep,
            best,
        });
    }
    Ok(Iterative {
        twitch: ev.twitch().clone(),
        stages,
    })
}
