//! Property tests: whatever bytes a record file or `dataset.json` holds, the reader
//! returns a value or an error, never panics; every accepted record is valid.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use super::dataset_support;

use std::path::Path;

use dataset_support::small_dataset;
use fes_dataset::{DataSet, FORCE_SLACK, WriteMode, parse_record_csv};
use fes_testkit::Scratch;
use proptest::prelude::*;

/// Checks the invariants of an accepted record.
fn assert_valid(cols: &fes_dataset::Columns) {
    let (t, p, f) = (&cols.t_ms, &cols.pulse, &cols.force);
    assert!(t.len() >= 2 && t.len() == p.len() && t.len() == f.len());
    assert!(cols.decided.as_ref().is_none_or(|d| d.len() == t.len()));
    assert!(t[0] >= 0.0 && t.windows(2).all(|w| w[1] > w[0]));
    assert!(
        f.iter()
            .all(|x| x.is_finite() && (-FORCE_SLACK..=1.0 + FORCE_SLACK).contains(x))
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// Arbitrary bytes.
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        if let Ok(cols) = parse_record_csv(Path::new("r.csv"), &bytes, 1e-3) {
            assert_valid(&cols);
        }
    }

    /// Bytes drawn from the CSV alphabet after a valid header, so parsing gets deep.
    #[test]
    fn csv_like_text_never_panics(body in "[0-9,.\\-eEinfaNn\r\n ]{0,300}") {
        let text = format!("t_ms,pulse,force\n{body}");
        if let Ok(cols) = parse_record_csv(Path::new("r.csv"), text.as_bytes(), 1e-3) {
            assert_valid(&cols);
        }
    }

    /// Mostly valid rows with one mutated byte.
    #[test]
    fn mutated_valid_file_never_panics(pos in 0usize..200, byte in any::<u8>()) {
        let mut bytes = b"t_ms,pulse,force\n0,1,0\n1,0,0.25\n2,0,0.5\n3,1,1\n4,0,0.75\n5,0,0.5\n".to_vec();
        let i = pos % bytes.len();
        bytes[i] = byte;
        if let Ok(cols) = parse_record_csv(Path::new("r.csv"), &bytes, 1e-3) {
            assert_valid(&cols);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// Arbitrary bytes in `dataset.json` give an error, never a panic.
    #[test]
    fn arbitrary_meta_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        let dir = Scratch::new("fuzz-meta");
        small_dataset().write(dir.path(), WriteMode::Overwrite).expect("write");
        std::fs::write(dir.join("dataset.json"), &bytes).expect("write");
        prop_assert!(DataSet::read(dir.path()).is_err());
    }
}
