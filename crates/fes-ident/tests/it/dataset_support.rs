//! Helpers shared by the data-set tests: a small valid data set (their scratch directories
//! are `fes_testkit::Scratch`).

use fes_dataset::{DataSet, Header, Record, Split};

/// Three records of five samples at 1 ms: two train, one test.
pub fn small_dataset() -> DataSet {
    let rec = |i: usize, pulses: [bool; 5], force: [f64; 5]| {
        Record::uniform(
            format!("record_{i:03}.csv"),
            "random",
            1e-3,
            pulses.to_vec(),
            force.to_vec(),
        )
    };
    DataSet {
        header: Header {
            source: "test".into(),
            preset: Some("fast".into()),
            parameters: [("tauc".to_string(), 0.01), ("a".to_string(), 6000.0)]
                .into_iter()
                .collect(),
            seed: Some(1),
            noise: serde_json::json!({ "noise_std_n": 1.2 }),
            protocol: serde_json::json!({ "kind": "thesis" }),
            scale_n: 123.25,
            offset_n: 4.5,
            ts_s: 1e-3,
            split: Split {
                train: vec![0, 1],
                test: vec![2],
            },
        },
        records: vec![
            rec(
                0,
                [true, false, false, false, false],
                [0.0, 0.0, 0.1, 0.5, 0.3],
            ),
            rec(
                1,
                [true, false, true, false, false],
                [0.0, -0.003, 0.2, 1.0, 0.7],
            ),
            rec(
                2,
                [false, true, false, false, false],
                [0.001, 0.0, 0.0, 0.15, 1.0 / 3.0],
            ),
        ],
    }
}
