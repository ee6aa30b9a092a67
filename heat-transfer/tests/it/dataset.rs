//! `--data DIR`: the E.2 experiments written as the `fes-dataset/2` data set the study
//! identifies from.

use fes_dataset::signals::SignalSet;
use sim_heat::HeatParams;

#[test]
fn the_experiments_are_written_as_the_study_reads_them() {
    let dir = fes_testkit::Scratch::new("heat-transfer-data");
    let p = HeatParams::default();
    heat_transfer::write_dataset(&p, 2, &dir).unwrap();
    let read = SignalSet::read(&dir).unwrap();
    assert_eq!(read, sim_heat::experiment::dataset(&p, 2).unwrap());
    assert_eq!(read.header.seed, Some(2));
    // A data set already there is not overwritten.
    let e = heat_transfer::write_dataset(&p, 3, &dir).unwrap_err();
    assert!(matches!(e, heat_transfer::StudyError::Dataset(_)), "{e:?}");
    assert_eq!(SignalSet::read(&dir).unwrap(), read);
}
