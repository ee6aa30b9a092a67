//! The constant-frequency train method (thesis 6.3, Fig. 6.3): FTIpP of trains of
//! 1..=N pulses at constant inter-pulse intervals (thesis: 1-10 pulses, IPI 2-100 ms), as a
//! surface over (pulses, IPI).

use rayon::prelude::*;

use super::{Evaluator, ForceResponse, OspError, PatternResult, ipi_range};

/// FTIpP over (number of pulses, IPI).
#[derive(Debug, Clone, PartialEq)]
pub struct TrainSurface {
    /// Pulse counts, 1..=N.
    pub pulses: Vec<usize>,
    /// Inter-pulse intervals, samples.
    pub ipis: Vec<usize>,
    /// `results[i][j]`: `pulses[i]` pulses at IPI `ipis[j]` (first pulse at sample 0).
    pub results: Vec<Vec<PatternResult>>,
}

impl TrainSurface {
    /// The FTIpP grid, `[pulse count][IPI]`.
    pub fn ftipp(&self) -> Vec<Vec<f64>> {
        self.results
            .iter()
            .map(|row| row.iter().map(|r| r.ftipp).collect())
            .collect()
    }

    /// The (pulse count, IPI in samples, FTIpP) of the largest FTIpP (first on ties, in
    /// the order of increasing pulse count then IPI).
    pub fn best(&self) -> (usize, usize, f64) {
        let mut best = (self.pulses[0], self.ipis[0], f64::NEG_INFINITY);
        for (i, row) in self.results.iter().enumerate() {
            for (j, r) in row.iter().enumerate() {
                if r.ftipp > best.2 {
                    best = (self.pulses[i], self.ipis[j], r.ftipp);
                }
            }
        }
        best
    }
}

/// Pulse sample indices of `n` pulses `ipi` samples apart from sample 0.
pub fn constant_ipi_train(n: usize, ipi: usize) -> Vec<usize> {
    (0..n).map(|j| j * ipi).collect()
}

/// The surface for 1..=`max_pulses` pulses and IPIs `ipi_min..=ipi_max` samples (in
/// parallel); `progress` is called once per pattern done.
pub fn train_surface<R: ForceResponse + ?Sized>(
    ev: &Evaluator<'_, R>,
    max_pulses: usize,
    ipi_min: usize,
    ipi_max: usize,
    progress: &(dyn Fn() + Sync),
) -> Result<TrainSurface, OspError> {
    if max_pulses == 0 {
        return Err(OspError::Settings {
            method: "the train surface",
            setting: "max_pulses (per train)",
            value: max_pulses,
            min: 1,
            max: None,
        });
    }
    let ipis = ipi_range(ipi_min, ipi_max)?;
    let pulses: Vec<usize> = (1..=max_pulses).collect();
    let cells: Vec<(usize, usize)> = pulses
        .iter()
        .flat_map(|&n| ipis.iter().map(move |&ipi| (n, ipi)))
        .collect();
    let flat: Vec<PatternResult> = cells
        .par_iter()
        .map(|&(n, ipi)| {
            let r = ev.evaluate(&constant_ipi_train(n, ipi));
            progress();
            r
        })
        .collect::<Result<_, _>>()?;
    let results = flat.chunks(ipis.len()).map(|c| c.to_vec()).collect();
    Ok(TrainSurface {
        pulses,
        ipis,
        results,
    })
}
