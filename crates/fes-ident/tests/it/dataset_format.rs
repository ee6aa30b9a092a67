//! The data-set format: exact round trip, overwrite protection, and a clear error naming
//! file, line and field for every violation the reader must catch.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use super::dataset_support;

use std::fs;

use dataset_support::small_dataset;
use fes_dataset::{DataSet, FormatError, META_FILE, ReadError, WriteError, WriteMode};
use fes_testkit::Scratch;

/// Writes the small data set and returns the scratch dir holding it.
fn written() -> Scratch {
    let dir = Scratch::new("fmt");
    small_dataset()
        .write(dir.path(), WriteMode::Overwrite)
        .expect("write");
    dir
}

/// Replaces the content of a file of the written data set.
fn put(dir: &Scratch, name: &str, content: &str) {
    fs::write(dir.join(name), content).expect("write test file");
}

/// Reads and returns the error message, failing if the read succeeds.
fn read_err(dir: &Scratch) -> String {
    match DataSet::read(dir.path()) {
        Ok(_) => panic!("the reader accepted an invalid data set"),
        Err(e) => e.to_string(),
    }
}

/// Every value written comes back bit for bit (shortest round-trip number format).
#[test]
fn round_trip_is_exact() {
    let dir = written();
    let back = DataSet::read(dir.path()).expect("read back");
    assert_eq!(back, small_dataset());
    assert_eq!(back.train().count(), 2);
    assert_eq!(back.test().count(), 1);
    let csv = fs::read_to_string(dir.join("record_001.csv")).expect("csv");
    assert!(
        csv.starts_with("t_ms,pulse,force\n0,1,0\n1,0,-0.003\n"),
        "{csv}"
    );
}

/// A recording's records carry the decisions beside the delivered pulses (a fourth
/// column, `decided`): they round-trip, the differences are counted both ways, a
/// three-column record reads as "the pulses are the decisions", and a fourth column of
/// another name or a value other than 0/1 is refused by name.
#[test]
fn the_decided_column_round_trips_and_counts_what_was_not_delivered() {
    let dir = Scratch::new("fmt-decided");
    let mut ds = small_dataset();
    // Record 0: the second decided pulse was refused by the driver (not delivered).
    let r = &mut ds.records[0];
    let mut decided = r.pulse.clone();
    let k = decided
        .iter()
        .position(|&p| !p)
        .expect("a sample without a pulse");
    decided[k] = true;
    r.decided = Some(decided);
    ds.write(dir.path(), WriteMode::Overwrite).expect("write");
    let back = DataSet::read(dir.path()).expect("read back");
    assert_eq!(back, ds);
    assert_eq!(back.undelivered(), (1, 0));
    assert_eq!(back.records[1].undelivered(), (0, 0));
    assert_eq!(back.records[1].decided, None);
    let csv = fs::read_to_string(dir.join(&back.records[0].file)).expect("csv");
    assert!(csv.starts_with("t_ms,pulse,force,decided\n"), "{csv}");
    // Delivered but not decided (a foreign pulse) counts the other way.
    let mut other = ds.clone();
    let r = &mut other.records[0];
    r.decided = Some(r.pulse.iter().map(|_| false).collect());
    let pulses = r.pulses();
    assert_eq!(other.undelivered().1, pulses);
    // A wrong fourth column and a wrong value.
    let file = back.records[0].file.clone();
    put(&dir, &file, "t_ms,pulse,force,wanted\n0,1,0,1\n1,0,0.1,0\n");
    assert!(
        read_err(&dir).contains("extra column(s) `wanted`"),
        "{}",
        read_err(&dir)
    );
    put(
        &dir,
        &file,
        "t_ms,pulse,force,decided\n0,1,0,2\n1,0,0.1,0\n",
    );
    let e = read_err(&dir);
    assert!(e.contains("decided") && e.contains(":2"), "{e}");
}

/// A non-empty directory is refused without overwriting; overwriting replaces only the
/// previous data set's files.
#[test]
fn refuses_non_empty_dir_and_overwrites_only_its_files() {
    let dir = written();
    put(&dir, "notes.txt", "keep me");
    let err = small_dataset()
        .write(dir.path(), WriteMode::CreateNew)
        .expect_err("must refuse");
    assert!(matches!(err, WriteError::DirNotEmpty { .. }), "{err}");
    let mut smaller = small_dataset();
    smaller.records.truncate(2);
    smaller.header.split.train = vec![0];
    smaller.header.split.test = vec![1];
    smaller
        .write(dir.path(), WriteMode::Overwrite)
        .expect("overwrite");
    assert!(!dir.join("record_002.csv").exists());
    assert!(dir.join("notes.txt").exists());
    assert_eq!(DataSet::read(dir.path()).expect("read").records.len(), 2);
}

/// An invalid data set writes nothing.
#[test]
fn invalid_data_set_writes_nothing() {
    let dir = Scratch::new("fmt-invalid");
    let target = dir.join("out");
    let mut ds = small_dataset();
    ds.records[1].force[2] = f64::NAN;
    let err = ds
        .write(&target, WriteMode::CreateNew)
        .expect_err("must refuse");
    assert!(
        err.to_string().contains("record_001.csv:4: field `force`"),
        "{err}"
    );
    assert!(!target.exists());
}

#[test]
fn missing_dir() {
    let dir = Scratch::new("fmt-missing");
    let err = DataSet::read(dir.join("nope")).expect_err("missing");
    assert!(matches!(err, ReadError::MissingDir { .. }));
    assert!(err.to_string().contains("nope"), "{err}");
}

#[test]
fn missing_meta_and_missing_record_file() {
    let dir = written();
    fs::remove_file(dir.join("record_002.csv")).expect("rm");
    let msg = read_err(&dir);
    assert!(msg.contains("record_002.csv"), "{msg}");
    fs::remove_file(dir.join(META_FILE)).expect("rm");
    let msg = read_err(&dir);
    assert!(msg.contains("dataset.json"), "{msg}");
}

/// Each CSV violation and the exact message fragment naming file, line and field.
#[test]
fn csv_violations_name_file_line_and_field() {
    let cases: &[(&str, &str)] = &[
        (
            "t_ms,pulse\n0,1\n1,0\n2,0\n3,0\n4,0\n",
            "record_000.csv:1: header `t_ms,pulse`: missing column(s) `force`",
        ),
        (
            "t_ms,pulse,force,extra\n",
            "record_000.csv:1: header `t_ms,pulse,force,extra`: extra column(s) `extra`",
        ),
        ("pulse,t_ms,force\n", "columns repeated or out of order"),
        (
            "t_ms,pulse,force\n0,1,0\n1,0\n",
            "record_000.csv:3: 2 field(s), expected 3",
        ),
        (
            "t_ms,pulse,force\n0,1,0\n1,0,0,7\n",
            "record_000.csv:3: 4 field(s), expected 3",
        ),
        (
            "t_ms,pulse,force\n0,1,0\n1,0,abc\n",
            "record_000.csv:3: field `force`: `abc` is not a number",
        ),
        (
            "t_ms,pulse,force\n0,1,0\n1,0,NaN\n",
            "record_000.csv:3: field `force`: NaN is not finite",
        ),
        (
            "t_ms,pulse,force\n0,1,0\n1,0,inf\n",
            "record_000.csv:3: field `force`: inf is not finite",
        ),
        (
            "t_ms,pulse,force\n0,1,0\n1,0,42.5\n",
            "record_000.csv:3: field `force`: 42.5 is outside",
        ),
        (
            "t_ms,pulse,force\n-1,1,0\n0,0,0\n",
            "record_000.csv:2: field `t_ms`: -1 is negative",
        ),
        (
            "t_ms,pulse,force\n0,1,0\n1,0,0\n1,0,0\n",
            "record_000.csv:4: field `t_ms`: 1 does not increase",
        ),
        (
            "t_ms,pulse,force\n0,1,0\n2,0,0\n",
            "record_000.csv:3: field `t_ms`: step 2 ms differs from ts_s = 1 ms",
        ),
        (
            "t_ms,pulse,force\n0,1,0\nx,0,0\n",
            "record_000.csv:3: field `t_ms`: `x` is not a number",
        ),
        (
            "t_ms,pulse,force\n0,2,0\n1,0,0\n",
            "record_000.csv:2: field `pulse`: `2` is not 0 or 1",
        ),
        (
            "t_ms,pulse,force\n0,0.5,0\n1,0,0\n",
            "record_000.csv:2: field `pulse`: `0.5` is not 0 or 1",
        ),
        (
            "t_ms,pulse,force\n0,1,0\n",
            "record_000.csv: 1 sample(s); a record needs at least 2",
        ),
        ("", "record_000.csv:1: header ``: the file is empty"),
        (
            "t_ms,pulse,force\n0,1,0\n\n1,0,0\n",
            "record_000.csv:3: 0 field(s), expected 3",
        ),
        (
            "t_ms,pulse,force\n0,1,0\n1,0,0\n",
            "record_000.csv: samples is 2, but dataset.json lists 5",
        ),
        (
            "t_ms,pulse,force\n0,0,0\n1,0,0\n2,0,0\n3,0,0\n4,0,0\n",
            "record_000.csv: pulses is 0, but dataset.json lists 1",
        ),
    ];
    for (content, expected) in cases {
        let dir = written();
        put(&dir, "record_000.csv", content);
        let msg = read_err(&dir);
        assert!(
            msg.contains(expected),
            "content {content:?}\n got: {msg}\nwant: {expected}"
        );
    }
    let dir = written();
    fs::write(
        dir.join("record_000.csv"),
        b"t_ms,pulse,force\n0,1,0\n1,\xff,0\n",
    )
    .expect("write");
    let msg = read_err(&dir);
    assert!(msg.contains("record_000.csv:3: not UTF-8 text"), "{msg}");
}

/// Windows line ends and a byte-order mark (spreadsheet exports) are accepted.
#[test]
fn crlf_and_bom_are_accepted() {
    let dir = written();
    put(
        &dir,
        "record_000.csv",
        "\u{feff}t_ms,pulse,force\r\n0,1,0\r\n1,0,0\r\n2,0,0.1\r\n3,0,0.5\r\n4,0,0.3\r\n\r\n",
    );
    let ds = DataSet::read(dir.path()).expect("read");
    assert_eq!(ds.records[0].force, vec![0.0, 0.0, 0.1, 0.5, 0.3]);
}

/// Each metadata violation and the message fragment naming the field.
#[test]
fn meta_violations_name_the_field() {
    let meta = |dir: &Scratch| -> serde_json::Value {
        serde_json::from_str(&fs::read_to_string(dir.join(META_FILE)).expect("meta")).expect("json")
    };
    type Edit = fn(&mut serde_json::Value);
    let cases: &[(Edit, &str)] = &[
        (
            |m| m["schema"] = "fes-dataset/2".into(),
            "field `schema` is \"fes-dataset/2\", expected \"fes-dataset/1\"",
        ),
        (
            |m| {
                m.as_object_mut().map(|o| o.remove("schema"));
            },
            "field `schema` is missing",
        ),
        (
            |m| {
                m.as_object_mut().map(|o| o.remove("scale_n"));
            },
            "missing field `scale_n`",
        ),
        (
            |m| m["scale_n"] = (-1.0).into(),
            "field `scale_n`: -1 is not a scale > 0 N",
        ),
        (
            |m| m["ts_s"] = 0.0.into(),
            "field `ts_s`: 0 is not a sample period > 0 s",
        ),
        (|m| m["ts_s"] = "1ms".into(), "invalid type: string \"1ms\""),
        (
            |m| m["split"]["train"] = serde_json::json!([]),
            "field `split.train`: the train split is empty",
        ),
        (
            |m| m["split"]["test"] = serde_json::json!([]),
            "field `split.test`: the test split is empty",
        ),
        (
            |m| m["split"]["test"] = serde_json::json!([7]),
            "field `split.test`: record index 7 is out of range",
        ),
        (
            |m| m["split"]["test"] = serde_json::json!([1]),
            "field `split`: record 1 is in both train and test",
        ),
        (
            |m| m["records"][1]["file"] = "../etc/passwd".into(),
            "field `records[1].file`: `../etc/passwd` is not a plain file name",
        ),
        (
            |m| m["records"][1]["file"] = "record_000.csv".into(),
            "field `records[1].file`: `record_000.csv` is listed twice",
        ),
        (
            |m| {
                if let Some(a) = m["records"].as_array_mut() {
                    a.truncate(1);
                }
            },
            "field `records`: 1 record(s); a data set needs at least 2",
        ),
    ];
    for (edit, expected) in cases {
        let dir = written();
        let mut m = meta(&dir);
        edit(&mut m);
        put(
            &dir,
            META_FILE,
            &serde_json::to_string_pretty(&m).expect("json"),
        );
        let msg = read_err(&dir);
        assert!(msg.contains("dataset.json"), "{msg}");
        assert!(msg.contains(expected), "got: {msg}\nwant: {expected}");
    }
    let dir = written();
    put(&dir, META_FILE, "{ \"schema\": \"fes-dataset/1\", ");
    let msg = read_err(&dir);
    assert!(msg.contains("dataset.json:1:"), "{msg}");
}

/// `validate` reports what the reader would, before anything is written.
#[test]
fn validate_matches_reader() {
    let mut ds = small_dataset();
    ds.records[2].t_ms[3] = ds.records[2].t_ms[2];
    let err = ds.validate("somewhere").expect_err("invalid");
    assert!(
        matches!(
            err,
            FormatError::Value {
                line: 5,
                field: "t_ms",
                ..
            }
        ),
        "{err}"
    );
    assert!(
        err.to_string().starts_with("somewhere/record_002.csv:5"),
        "{err}"
    );
}
