//! Helpers shared by the data-set tests: scratch directories and a small valid data set.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use fes_dataset::{DataSet, Header, Record, Split};

/// A fresh, empty scratch directory, removed on drop.
pub struct Scratch(pub PathBuf);

impl Scratch {
    /// A new directory under the system temp dir, unique per process and call.
    pub fn new(tag: &str) -> Scratch {
        static N: AtomicUsize = AtomicUsize::new(0);
        let n = N.fetch_add(1, Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("rt-core-{tag}-{}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("create scratch dir");
        Scratch(dir)
    }

    /// Path of `name` inside it.
    pub fn join(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }

    /// The directory.
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

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
