//! The importer of foreign tables (`fes dataset import`) on any bytes, under three option
//! sets (a time column in seconds split by gaps, a fixed rate split by a record column with
//! estimated offset and scale, a list of pulse times): an error, or a data set that passes
//! the format's validation.
#![no_main]

use std::path::Path;

use fes_dataset::import::{
    ColumnRef, ImportOptions, Level, Pulses, TimeSource, import, parse_pulse_times,
};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&which, rest)) = data.split_first() else {
        return;
    };
    let col = |s: &str| ColumnRef::parse(s);
    let mut o = ImportOptions::new(
        TimeSource::Column(col("t")),
        col("f"),
        Pulses::Column {
            column: col("p"),
            edges: which & 1 == 1,
        },
    );
    let input = match which % 3 {
        0 => {
            o.force_offset = Level::Given(0.0);
            o.force_scale = Level::Given(1.0);
            o.split_gap_s = Some(0.01);
            rest
        }
        1 => {
            o.time = TimeSource::Rate { hz: 2000.0 };
            o.force = ColumnRef::Number(1);
            o.pulses = Pulses::Column {
                column: ColumnRef::Number(2),
                edges: false,
            };
            o.record_column = Some(ColumnRef::Number(3));
            rest
        }
        _ => {
            // The first line is the list of pulse times, the rest the table.
            let cut = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
            let list: Vec<u8> = rest[..cut]
                .iter()
                .map(|&b| if b == b' ' { b'\n' } else { b })
                .collect();
            let Ok(times) = parse_pulse_times(Path::new("p.txt"), &list) else {
                return;
            };
            o.pulses = Pulses::Times {
                path: "p.txt".into(),
                times,
            };
            o.split_gap_s = Some(0.005);
            &rest[cut.min(rest.len())..]
        }
    };
    if let Ok(imported) = import(Path::new("in.csv"), input, &o) {
        let ds = imported.dataset;
        assert!(ds.validate(Path::new("out")).is_ok());
        assert!(ds.records.len() >= 2);
        assert_eq!(
            ds.records.iter().map(|r| r.pulses()).sum::<usize>(),
            imported.report.pulses
        );
    }
});
