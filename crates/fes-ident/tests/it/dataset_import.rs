//! The importer (`fes_dataset::import`): foreign tables at other rates, units and layouts
//! onto the format's grid, and every refusal naming its line and column. The end-to-end
//! round trip (sim-muscle data written in a foreign layout, imported by `fes dataset
//! import`, identified to the same model) is workbench/tests/it/dataset_import_cli.rs.

use std::path::{Path, PathBuf};

use fes_dataset::DataSet;
use fes_dataset::import::{
    ColumnRef, Delimiter, ImportError, ImportOptions, Level, Pulses, SplitSpec, TimeSource,
    TimeUnit, import, parse_pulse_times,
};

fn path() -> PathBuf {
    PathBuf::from("in.csv")
}

fn name(s: &str) -> ColumnRef {
    ColumnRef::parse(s)
}

/// Options for a `time_s,force,stim` table: seconds, given offset 0 and scale 10 N.
fn opts() -> ImportOptions {
    let mut o = ImportOptions::new(
        TimeSource::Column(name("time_s")),
        name("force"),
        Pulses::Column {
            column: name("stim"),
            edges: false,
        },
    );
    o.force_offset = Level::Given(0.0);
    o.force_scale = Level::Given(10.0);
    o.split_gap_s = Some(0.01);
    o
}

fn run(text: &str, o: &ImportOptions) -> Result<DataSet, ImportError> {
    import(&path(), text.as_bytes(), o).map(|i| i.dataset)
}

fn err(text: &str, o: &ImportOptions) -> String {
    match run(text, o) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

/// Two records at 2.5 kHz (0.4 ms steps, 0..20 ms), 200 ms apart: force a ramp of
/// 0.1 N/ms from 2 N, pulses on the given steps of record 0 and record 1.
fn table(pulses0: &[usize], pulses1: &[usize]) -> String {
    let mut s = String::from("time_s,force,stim\n");
    for (r, pulses) in [pulses0, pulses1].iter().enumerate() {
        for j in 0..51 {
            let t = 0.2 * r as f64 + 0.0004 * j as f64;
            let f = 2.0 + 0.04 * j as f64;
            s.push_str(&format!(
                "{t:.4},{f:.2},{}\n",
                u8::from(pulses.contains(&j))
            ));
        }
    }
    s
}

#[test]
fn a_faster_table_is_resampled_onto_the_grid_with_its_pulses() {
    let text = table(&[2, 11, 50], &[0, 49]);
    let imported = import(&path(), text.as_bytes(), &opts()).unwrap();
    let ds = imported.dataset;
    assert_eq!(ds.records.len(), 2, "split at the 180 ms gap");
    for r in &ds.records {
        assert_eq!(r.len(), 21, "20 ms at 1 ms: 21 samples");
        assert_eq!(r.t_ms[20], 20.0);
        for (k, &f) in r.force.iter().enumerate() {
            // F = 2 + 0.1 t N, at t = k ms between input samples for odd k; normalised by
            // 10 N.
            let want = (2.0 + 0.1 * k as f64) / 10.0;
            assert!((f - want).abs() < 1e-12, "sample {k}: {f} vs {want}");
        }
        assert_eq!(r.kind, "imported");
    }
    let ticks = |i: usize| -> Vec<usize> { (0..21).filter(|&k| ds.records[i].pulse[k]).collect() };
    // Steps 2, 11, 50 are at 0.8, 4.4, 20 ms; 0 and 49 at 0 and 19.6 ms.
    assert_eq!(ticks(0), vec![1, 4, 20]);
    assert_eq!(ticks(1), vec![0, 20]);
    assert_eq!(ds.header.split.train, vec![0]);
    assert_eq!(ds.header.split.test, vec![1]);
    assert_eq!(ds.header.scale_n, 10.0);
    assert_eq!(imported.report.pulses, 5);
    assert!((imported.report.max_pulse_shift_ms - 0.4).abs() < 1e-9);
    assert!((imported.report.input_step_ms - 0.4).abs() < 1e-9);
    assert_eq!(imported.report.record_lines, vec![(2, 52), (53, 103)]);
    assert_eq!(ds.header.protocol["kind"], "import");
}

#[test]
fn two_pulses_on_one_tick_are_refused_naming_both_lines_and_edges_merge_a_run() {
    // Steps 2 and 3 (0.8 and 1.2 ms) both fall on tick 1.
    let text = table(&[2, 3], &[3]);
    let e = err(&text, &opts());
    assert!(
        e.starts_with("in.csv:5: column 3 `stim`: the pulse at t = 0.0012 s falls on the same 1 ms tick (record 0, sample 1) as the pulse of line 4"),
        "{e}"
    );
    assert!(e.contains("pulse edges"), "{e}");
    // As edges, the run of two non-zero samples is one pulse, at its first sample.
    let mut o = opts();
    o.pulses = Pulses::Column {
        column: name("stim"),
        edges: true,
    };
    let ds = run(&text, &o).unwrap();
    assert_eq!(ds.records[0].pulses(), 1);
    assert!(ds.records[0].pulse[1]);
}

#[test]
fn whitespace_columns_by_number_at_a_fixed_rate_with_auto_normalisation() {
    // No header (the first line is numbers), no time column: 1 kHz; records by a column.
    let mut text = String::from("# exported by a rig\n");
    for r in 0..3 {
        for k in 0..10 {
            let f = if k < 3 { 5.0 } else { 5.0 + 2.0 * k as f64 };
            let amp = if k == 3 { 12.5 } else { 0.0 };
            text.push_str(&format!("  {f} {amp}   trial{r}\n"));
        }
    }
    let mut o = ImportOptions::new(
        TimeSource::Rate { hz: 1000.0 },
        name("1"),
        Pulses::Column {
            column: ColumnRef::Number(2),
            edges: false,
        },
    );
    o.record_column = Some(name("3"));
    o.split = SplitSpec::Test(vec![1]);
    let imported = import(&path(), text.as_bytes(), &o).unwrap();
    let ds = imported.dataset;
    assert_eq!(ds.records.len(), 3);
    let kinds: Vec<&str> = ds.records.iter().map(|r| r.kind.as_str()).collect();
    assert_eq!(kinds, ["trial0", "trial1", "trial2"]);
    assert_eq!(ds.header.split.train, vec![0, 2]);
    assert_eq!(ds.header.split.test, vec![1]);
    // Offset: the samples up to the first pulse (k <= 3) are 5, 5, 5, 11: mean 6.5 N.
    assert_eq!(ds.header.offset_n, 6.5);
    // Scale: the largest offset-free sample, 23 - 6.5.
    assert_eq!(ds.header.scale_n, 16.5);
    let max = ds.records[0].force.iter().copied().fold(f64::MIN, f64::max);
    assert_eq!(max, 1.0);
    for r in &ds.records {
        assert_eq!(r.len(), 10);
        assert_eq!(r.pulse.iter().position(|&p| p), Some(3));
    }
    // A column named by a name the input has not: the columns are listed.
    o.force = name("force");
    let e = import(&path(), text.as_bytes(), &o)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("force column `force`: the input has no header line (its first line holds a number): name columns by number; the columns are 1 `#1`, 2 `#2`, 3 `#3`"),
        "{e}"
    );
}

#[test]
fn pulse_times_from_a_list_go_to_their_records_and_gaps_are_refused() {
    let mut text = String::from("\"Time (ms)\";\"Force (mN)\"\n");
    for r in 0..2 {
        for k in 0..50 {
            let t = 1000.0 * r as f64 + 2.0 * k as f64;
            text.push_str(&format!("{t};{}\n", 1000.0 + 100.0 * k as f64));
        }
    }
    let list = "time\n10\n# a comment\n\n1020.4\n1097.9\n";
    let times = parse_pulse_times(Path::new("p.txt"), list.as_bytes()).unwrap();
    assert_eq!(times, vec![(2, 10.0), (5, 1020.4), (6, 1097.9)]);
    let mut o = ImportOptions::new(
        TimeSource::Column(name("time (ms)")),
        name("Force (mN)"),
        Pulses::Times {
            path: "p.txt".into(),
            times,
        },
    );
    o.time_unit = TimeUnit::Ms;
    o.delimiter = Delimiter::Semicolon;
    o.force_gain = 1e-3;
    o.force_offset = Level::Given(1.0);
    o.force_scale = Level::Given(10.0);
    o.split_gap_s = Some(0.1);
    let ds = run(&text, &o).unwrap();
    assert_eq!(ds.records.len(), 2);
    assert_eq!(ds.records[0].len(), 99, "0..98 ms");
    // Force at 3 ms: halfway between 1.1 N and 1.2 N; normalised (1.15 - 1) / 10.
    assert!((ds.records[0].force[3] - 0.015).abs() < 1e-12);
    let p1: Vec<usize> = (0..99).filter(|&k| ds.records[1].pulse[k]).collect();
    assert_eq!(p1, vec![20, 98]);
    assert!(ds.records[0].pulse[10]);
    // A pulse in the gap between the records.
    let times = parse_pulse_times(Path::new("p.txt"), b"10\n500\n").unwrap();
    o.pulses = Pulses::Times {
        path: "p.txt".into(),
        times,
    };
    let e = err(&text, &o);
    assert_eq!(
        e,
        "p.txt:2: pulse at t = 500 ms is in no record: it is in the gap after record 0 (to 98 ms), before record 1 (from 1000 ms)"
    );
    // The same time twice.
    let times = parse_pulse_times(Path::new("p.txt"), b"10\n10.2\n").unwrap();
    o.pulses = Pulses::Times {
        path: "p.txt".into(),
        times,
    };
    let e = err(&text, &o);
    assert!(e.starts_with("p.txt:2: column 1 `pulse time`: the pulse at t = 10.2 ms falls on the same 1 ms tick (record 0, sample 10) as the pulse of line 1"), "{e}");
    // A bad time in the list.
    let e = parse_pulse_times(Path::new("p.txt"), b"10\n1x\n")
        .unwrap_err()
        .to_string();
    assert_eq!(
        e,
        "p.txt:2: column 1 `pulse time`: `1x` is not a finite number"
    );
}

#[test]
fn every_bad_value_is_named_by_line_and_column() {
    let good = table(&[2], &[3]);
    let edit = |line: usize, new: &str| -> String {
        good.lines()
            .enumerate()
            .map(|(i, l)| if i + 1 == line { new } else { l })
            .collect::<Vec<_>>()
            .join("\n")
    };
    let cases: Vec<(String, &str)> = vec![
        (
            edit(5, "0.0012,abc,0"),
            "in.csv:5: column 2 `force`: `abc` is not a number",
        ),
        (
            edit(5, "0.0012,,0"),
            "in.csv:5: column 2 `force`: empty field",
        ),
        (
            edit(5, "0.0012,NaN,0"),
            "in.csv:5: column 2 `force`: NaN is not finite",
        ),
        (
            edit(5, "0.0008,2.3,0"),
            "in.csv:5: column 1 `time_s`: time 0.0008 s does not increase (line 4: 0.0008 s)",
        ),
        (
            edit(5, "0.0012,2.3,-1"),
            "in.csv:5: column 3 `stim`: -1 is negative; a pulse is > 0, no pulse 0",
        ),
        (
            edit(5, "0.0012,2.3"),
            "in.csv:5: 2 field(s), expected 3 (as line 1)",
        ),
        (
            edit(5, "0.0012,15,0"),
            "in.csv:5: column 2 `force`: force 15 N normalises to 1.5, outside [-0.1, 1.1] (offset_n 0 N, scale_n 10 N); check the force gain, offset and scale",
        ),
        (
            edit(5, "0.0012 2.3 0"),
            "in.csv:5: 1 field(s), expected 3 (as line 1) (is the delimiter right? see the delimiter option)",
        ),
    ];
    for (text, want) in cases {
        assert_eq!(err(&text, &opts()), want);
    }
    // Columns that are not there.
    let mut o = opts();
    o.force = name("force_n");
    assert_eq!(
        err(&good, &o),
        "in.csv: force column `force_n`: no such column; the columns are 1 `time_s`, 2 `force`, 3 `stim`"
    );
    o.force = ColumnRef::Number(4);
    assert!(err(&good, &o).contains("force column `4`: there are 3 column(s)"));
    // No gap: one record.
    let mut o = opts();
    o.split_gap_s = None;
    assert_eq!(
        err(&good, &o),
        "in.csv: 1 record(s); a data set needs at least 2 (train and test): records are split by a time gap (split gap) or a record column; neither was given"
    );
    // A record of one sample.
    let short = format!("{good}1.0,2,0\n");
    assert_eq!(
        err(&short, &opts()),
        "in.csv:104-104: record 2 spans 0 ms, less than two samples of 1 ms; check the split gap or the record column"
    );
    // Options.
    let mut o = opts();
    o.force_scale = Level::Given(0.0);
    assert_eq!(err(&good, &o), "force scale: 0 is not a scale > 0 N");
    let mut o = opts();
    o.split = SplitSpec::TrainFirst(2);
    assert_eq!(
        err(&good, &o),
        "train records: 2 training records leave the train or the test split empty (2 records, numbered from 0)"
    );
    let mut o = opts();
    o.split = SplitSpec::Test(vec![5]);
    assert_eq!(
        err(&good, &o),
        "test records: record 5 does not exist (2 records, numbered from 0)"
    );
    assert_eq!(err("time_s,force,stim\n", &opts()), "in.csv: no data lines");
    assert_eq!(
        import(&path(), b"time_s,force\n\xff\n", &opts())
            .unwrap_err()
            .to_string(),
        "in.csv:2: not UTF-8 text"
    );
}

/// What the importer writes reads back through the format's reader unchanged.
#[test]
fn an_import_writes_a_data_set_the_reader_accepts() {
    let text = table(&[2, 9], &[5]);
    let ds = run(&text, &opts()).unwrap();
    let dir = fes_testkit::Scratch::new("import");
    ds.write(&dir, fes_dataset::WriteMode::CreateNew).unwrap();
    let back = DataSet::read(&dir).unwrap();
    assert_eq!(back, ds);
}

/// A time in the wrong unit (ms read as s) makes a record of hours: refused by name
/// before any memory is taken for it.
#[test]
fn a_record_too_long_for_the_grid_is_refused() {
    let text = "time_s,force,stim\n0,0,0\n20000,0.5,1\n50000,0,0\n50001,0,0\n";
    let mut o = opts();
    o.split_gap_s = Some(25_000.0);
    assert_eq!(
        err(text, &o),
        "in.csv:2-3: record 0 spans 20000000 ms: more than 10000000 samples of 1 ms; check the time unit and the record split"
    );
}

mod never_panics {
    use super::*;
    use proptest::prelude::*;

    fn check(text: &[u8], o: &ImportOptions) {
        if let Ok(i) = import(&path(), text, o) {
            i.dataset.validate(Path::new("out")).unwrap();
            assert!(i.dataset.records.len() >= 2);
            let pulses: usize = i.dataset.records.iter().map(|r| r.pulses()).sum();
            assert_eq!(pulses, i.report.pulses);
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(1000))]

        /// Arbitrary bytes: an error or a valid data set, never a panic.
        #[test]
        fn arbitrary_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
            check(&bytes, &opts());
        }

        /// Table-like text under the option sets of the tests above.
        #[test]
        fn table_like_text(body in "[0-9,.;\\- \t\"eEa\n]{0,300}", which in 0u8..3) {
            let mut o = opts();
            match which {
                0 => {}
                1 => {
                    o.time = TimeSource::Rate { hz: 2000.0 };
                    o.force = ColumnRef::Number(1);
                    o.pulses = Pulses::Column { column: ColumnRef::Number(2), edges: true };
                    o.record_column = Some(ColumnRef::Number(3));
                    o.force_offset = Level::Auto;
                    o.force_scale = Level::Auto;
                }
                _ => {
                    o.pulses = Pulses::Times {
                        path: "p.txt".into(),
                        times: vec![(1, 0.0), (2, 0.0021), (3, 0.5)],
                    };
                }
            }
            let text = format!("time_s,force,stim\n{body}");
            check(text.as_bytes(), &o);
            check(body.as_bytes(), &o);
        }
    }
}
