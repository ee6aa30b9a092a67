//! Records drawn like thesis Fig. 5.2: pulses on top, normalised force below, the
//! selected records concatenated (the 30 s rests between them omitted).

use std::path::{Path, PathBuf};

use fes_dataset::DataSet;
use plotters::prelude::*;

/// Why a plot could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// No record was selected.
    #[error("no record selected to plot")]
    NoRecords,
    /// A selected record does not exist.
    #[error("record {index} does not exist: the data set has {count} records (0..{count})")]
    NoSuchRecord {
        /// The index asked for.
        index: usize,
        /// Records in the data set.
        count: usize,
    },
    /// The image size is unusable.
    #[error("image size {width}x{height} px: both must be within 200..=4000")]
    BadSize {
        /// Width, px.
        width: u32,
        /// Height, px.
        height: u32,
    },
    /// The output is neither a PNG nor an SVG file name.
    #[error("{}: the output must be a .png or .svg file", path.display())]
    NotPng {
        /// The path given.
        path: PathBuf,
    },
    /// Drawing or writing the image failed.
    #[error("{}: drawing failed: {source}", path.display())]
    Draw {
        /// The output file.
        path: PathBuf,
        /// What plotters reported.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

/// Records shown when none are named: the first three random records and the first
/// constant-frequency record, as in thesis Fig. 5.2; else the first four records.
pub fn default_selection(ds: &DataSet) -> Vec<usize> {
    let mut pick: Vec<usize> = ds
        .records
        .iter()
        .enumerate()
        .filter(|(_, r)| r.kind == "random")
        .map(|(i, _)| i)
        .take(3)
        .collect();
    if let Some(i) = ds
        .records
        .iter()
        .position(|r| r.kind.starts_with("constant"))
    {
        pick.push(i);
    }
    if pick.len() < 2 {
        pick = (0..ds.records.len().min(4)).collect();
    }
    pick
}

/// Draws `records` of `ds` into the PNG or SVG file `out` (by its extension) of `width` x
/// `height` pixels.
pub fn plot_records(
    ds: &DataSet,
    records: &[usize],
    title: &str,
    out: &Path,
    (width, height): (u32, u32),
) -> Result<(), PlotError> {
    if records.is_empty() {
        return Err(PlotError::NoRecords);
    }
    if let Some(&index) = records.iter().find(|&&i| i >= ds.records.len()) {
        return Err(PlotError::NoSuchRecord {
            index,
            count: ds.records.len(),
        });
    }
    if !(200..=4000).contains(&width) || !(200..=4000).contains(&height) {
        return Err(PlotError::BadSize { width, height });
    }
    let size = (width, height);
    let drawn = fes_figure::by_extension!(out, size, |root| {
        draw(root, ds, records, title, size)
            .map_err(|e| Box::new(e) as Box<dyn std::error::Error + Send + Sync>)
    });
    let Some(drawn) = drawn else {
        return Err(PlotError::NotPng {
            path: out.to_path_buf(),
        });
    };
    drawn.map_err(|source| PlotError::Draw {
        path: out.to_path_buf(),
        source,
    })
}

/// The drawing itself, on either backend.
fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    ds: &DataSet,
    records: &[usize],
    title: &str,
    size: (u32, u32),
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let ts_ms = ds.header.ts_s * 1e3;
    // Start time of each selected record on the concatenated axis.
    let mut starts = Vec::with_capacity(records.len());
    let mut total = 0.0;
    for &i in records {
        starts.push(total);
        total += ds.records[i].len() as f64 * ts_ms;
    }
    let selected = || records.iter().map(|&i| &ds.records[i]);
    let low = selected()
        .flat_map(|r| r.force.iter().copied())
        .fold(0.0, f64::min)
        .min(-0.02);

    root.fill(&WHITE)?;
    let root = root.titled(title, ("sans-serif", 18))?;
    let (upper, lower) = root.split_vertically(size.1 * 18 / 100);

    let mut top = fes_figure::pulse_strip(&upper).build_cartesian_2d(0.0..total, 0.0..1.25)?;
    top.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_labels(2)
        .y_label_formatter(&|y| format!("{y:.0}"))
        .y_desc("pulse")
        .draw()?;
    for (r, &t0) in selected().zip(&starts) {
        let pulses = r.pulse.iter().enumerate().filter(|(_, p)| **p);
        top.draw_series(pulses.map(|(k, _)| fes_figure::pulse_mark(t0 + k as f64 * ts_ms)))?;
    }

    let mut bottom = fes_figure::time_panel(&lower).build_cartesian_2d(0.0..total, low..1.08)?;
    bottom
        .configure_mesh()
        .light_line_style(WHITE.mix(0.0))
        .x_label_formatter(&|x| format!("{x:.0}"))
        .x_desc("time (ms), records concatenated, rests omitted")
        .y_desc("force (normalised)")
        .draw()?;
    for ((r, &t0), &i) in selected().zip(&starts).zip(records) {
        let line = r
            .force
            .iter()
            .enumerate()
            .map(|(k, &f)| (t0 + k as f64 * ts_ms, f));
        bottom.draw_series(LineSeries::new(line, BLUE.stroke_width(1)))?;
        if t0 > 0.0 {
            let separator = PathElement::new(vec![(t0, low), (t0, 1.08)], BLACK.mix(0.3));
            bottom.draw_series(std::iter::once(separator))?;
        }
        let label = format!("#{i} {}", r.kind);
        bottom.draw_series(std::iter::once(Text::new(
            label,
            (t0 + 8.0 * ts_ms, 1.04),
            ("sans-serif", 13),
        )))?;
    }
    root.present()?;
    Ok(())
}
