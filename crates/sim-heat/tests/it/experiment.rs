//! The experiments of E.2: counts and lengths, the test-voltage structure, the mean filter
//! and the normalisation, reproducibility from the seed.

use fes_dataset::WriteMode;
use fes_dataset::signals::{AnyDataSet, SignalSet, read_any};
use sim_heat::experiment::{Experiment, all_records, dataset, mean_filter, split};
use sim_heat::plant::HeatParams;

#[test]
fn four_experiments_with_the_thesis_counts_and_lengths() {
    let recs = all_records(&HeatParams::default(), 1).unwrap();
    assert_eq!(recs.len(), 9);
    let count = |e| recs.iter().filter(|r| r.experiment == e).count();
    for e in Experiment::ALL {
        assert_eq!(count(e), e.records(), "{e:?}");
    }
    for r in &recs {
        let n = (r.experiment.duration_s() / 0.05).round() as usize;
        assert_eq!(
            (r.alpha.len(), r.u.len(), r.y.len()),
            (n, n, n),
            "{}",
            r.name
        );
        for v in r.alpha.iter().chain(&r.u) {
            assert!((0.0..=1.0).contains(v), "{}: {v}", r.name);
        }
        for v in &r.y {
            assert!((-0.05..=1.05).contains(v), "{}: {v}", r.name);
        }
    }
    // Test-voltage: five angles of 50 s each, the same voltage sequence at each.
    let tv = recs
        .iter()
        .find(|r| r.experiment == Experiment::TestVoltage)
        .unwrap();
    let per = 1000;
    for i in 0..5 {
        assert!(
            tv.alpha[i * per..(i + 1) * per]
                .iter()
                .all(|&a| a == tv.alpha[i * per])
        );
        assert_eq!(tv.u[i * per..(i + 1) * per], tv.u[..per]);
    }
    let (train, test) = split();
    assert_eq!(train.len() + test.len(), 9);
    assert!(train.iter().all(|i| !test.contains(i)));
}

#[test]
fn records_are_reproducible_from_the_seed() {
    let p = HeatParams::default();
    assert_eq!(all_records(&p, 7).unwrap(), all_records(&p, 7).unwrap());
    assert_ne!(
        all_records(&p, 7).unwrap()[0].y,
        all_records(&p, 8).unwrap()[0].y
    );
}

#[test]
fn mean_filter_is_the_three_sample_average() {
    let y = [3.0, 6.0, 9.0, 0.0];
    assert_eq!(mean_filter(&y), vec![3.0, 4.5, 6.0, 5.0]);
}

/// The experiments written as a `fes-dataset/2` data set read back exactly.
#[test]
fn experiments_round_trip_through_the_data_set_format() {
    let dir = fes_testkit::Scratch::new("sim-heat-ds");
    let set = dataset(&HeatParams::default(), 1).unwrap();
    set.write(&dir, WriteMode::CreateNew).unwrap();
    let back = read_any(&dir).unwrap();
    let AnyDataSet::Signals(back) = back else {
        panic!("not read as signals")
    };
    assert_eq!(back, set);
    assert_eq!(back.header.ts_s, 0.05);
    assert_eq!(back.input_index("u"), Some(1));
    assert_eq!(SignalSet::clone(&back).records.len(), 9);
}
