//! The `sim-muscle` binary: output formats, data sets read back through
//! `fes_dataset`, determinism, and bad flags (clear error, non-zero exit, nothing
//! written).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use crate::support;

use std::fs;

use fes_dataset::DataSet;
use sim_muscle::muscle::{Muscle, MuscleConfig};
use sim_muscle::pattern::from_samples;
use sim_muscle::plant::Pulse;
use sim_muscle::preset::Preset;
use sim_muscle::simulate::simulate;
use support::{Scratch, run, run_ok};

/// Parses `t_ms,force_n` output.
fn parse_force(csv: &str) -> Vec<(usize, f64)> {
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("t_ms,force_n"));
    lines
        .map(|l| {
            let (t, f) = l.split_once(',').expect("two fields");
            (t.parse().expect("t_ms"), f.parse().expect("force_n"))
        })
        .collect()
}

/// `simulate` prints the library's force (to its 1e-6 N print precision), one row per
/// ms, the first nonzero sample 8 ms after the pulse with the default 7 ms delay.
#[test]
fn simulate_prints_the_model_force() {
    let rows = parse_force(&run_ok(&[
        "simulate",
        "--preset",
        "slow",
        "--pulses",
        "0,5,40",
        "--duration-ms",
        "300",
    ]));
    assert_eq!(rows.len(), 300);
    assert!(rows.iter().enumerate().all(|(k, (t, _))| *t == k));
    let mut m = Muscle::new(MuscleConfig::preset(Preset::Slow)).expect("valid");
    let lib = simulate(&mut m, &from_samples(&[0, 5, 40], 300), Pulse::SUPRAMAXIMAL);
    for ((_, f), g) in rows.iter().zip(&lib) {
        assert!((f - g).abs() <= 5e-7 + 1e-12 * g.abs(), "{f} vs {g}");
    }
    assert_eq!(rows.iter().position(|(_, f)| *f > 0.0), Some(8));
    // The same train as a frequency: 40 Hz for 100 ms = pulses at 0, 25, 50, 75, 100.
    let by_freq = run_ok(&[
        "simulate",
        "--preset",
        "fast",
        "--freq",
        "40",
        "--train-ms",
        "100",
        "--duration-ms",
        "200",
    ]);
    let by_list = run_ok(&[
        "simulate",
        "--preset",
        "fast",
        "--pulses",
        "0,25,50,75,100",
        "--duration-ms",
        "200",
    ]);
    assert_eq!(by_freq, by_list);
}

/// `--set`, `--emd-ms`, `--repeat-ms` and `--fatigue` change what they should.
#[test]
fn simulate_options() {
    let base = parse_force(&run_ok(&[
        "simulate",
        "--preset",
        "fast",
        "--pulses",
        "0",
        "--duration-ms",
        "200",
    ]));
    let doubled = parse_force(&run_ok(&[
        "simulate",
        "--preset",
        "fast",
        "--set",
        "a=12000",
        "--pulses",
        "0",
        "--duration-ms",
        "200",
    ]));
    for ((_, a), (_, b)) in base.iter().zip(&doubled) {
        assert!((2.0 * a - b).abs() <= 2e-6, "force is linear in A: {a} {b}");
    }
    let no_delay = parse_force(&run_ok(&[
        "simulate",
        "--preset",
        "fast",
        "--emd-ms",
        "0",
        "--pulses",
        "0",
        "--duration-ms",
        "200",
    ]));
    assert_eq!(no_delay.iter().position(|(_, f)| *f > 0.0), Some(1));
    let repeated = parse_force(&run_ok(&[
        "simulate",
        "--preset",
        "fast",
        "--pulses",
        "0",
        "--repeat-ms",
        "100",
        "--duration-ms",
        "300",
    ]));
    // The force 100 ms after a twitch has not fully decayed, so the second response is
    // the first plus that residue: larger, never smaller.
    assert!((0..100).all(|k| repeated[100 + k].1 >= base[k].1 - 1e-6));
    let args = [
        "--preset",
        "slow",
        "--freq",
        "33",
        "--train-ms",
        "1000",
        "--repeat-ms",
        "2000",
        "--duration-ms",
        "20000",
    ];
    let fresh = parse_force(&run_ok(&[&["simulate"][..], &args].concat()));
    let tired = parse_force(&run_ok(&[&["simulate", "--fatigue"][..], &args].concat()));
    let peak = |r: &[(usize, f64)], from: usize| {
        r[from..from + 2000].iter().map(|x| x.1).fold(0.0, f64::max)
    };
    assert!((peak(&fresh, 18000) - peak(&fresh, 0)).abs() < 1e-6);
    assert!(peak(&tired, 18000) < 0.9 * peak(&tired, 0));
}

/// `--measured` adds the sensor: seeded (same seed, same output), offset and noise as
/// given: offset 50 N, noise 0.5 N (the one pulse, at the last sample, shows no force),
/// so the samples average 50 N within 4 standard errors and scatter by 0.5 N within 20 %.
#[test]
fn simulate_measured() {
    let args = [
        "simulate",
        "--preset",
        "fast",
        "--pulses",
        "99",
        "--duration-ms",
        "100",
        "--measured",
    ];
    let noisy = [&args[..], &["--offset-n", "50", "--noise-std-n", "0.5"]].concat();
    let a = run_ok(&[&noisy[..], &["--seed", "9"]].concat());
    assert_eq!(a, run_ok(&[&noisy[..], &["--seed", "9"]].concat()));
    let rows = parse_force(&a);
    let n = rows.len() as f64;
    let mean = rows.iter().map(|r| r.1).sum::<f64>() / n;
    let sd = (rows.iter().map(|r| (r.1 - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    assert!((mean - 50.0).abs() < 4.0 * 0.5 / n.sqrt(), "mean {mean}");
    assert!((sd / 0.5 - 1.0).abs() < 0.2, "sd {sd}");
    assert_ne!(run_ok(&[&noisy[..], &["--seed", "10"]].concat()), a);
}

/// Reads `dir` back and checks it against the thesis protocol (5.1) for `preset`.
fn check_thesis_dataset(dir: &std::path::Path, preset: Preset, records: usize, samples: usize) {
    let ds = DataSet::read(dir).expect("the data set reads back");
    assert_eq!(ds.records.len(), records);
    assert_eq!(ds.header.preset.as_deref(), Some(preset.name()));
    assert_eq!(ds.header.ts_s, 1e-3);
    assert_eq!(ds.header.split.train, (0..30).collect::<Vec<_>>());
    assert_eq!(ds.header.split.test, (30..records).collect::<Vec<_>>());
    let max = ds
        .records
        .iter()
        .flat_map(|r| r.force.iter().copied())
        .fold(f64::MIN, f64::max);
    assert_eq!(max, 1.0);
    let (mut min_ipi, mut max_ipi) = (usize::MAX, 0);
    for (i, r) in ds.records.iter().enumerate() {
        assert_eq!(r.len(), samples, "record {i}");
        assert_eq!(r.file, format!("record_{i:03}.csv"));
        let pulses: Vec<usize> = (0..r.len()).filter(|&k| r.pulse[k]).collect();
        assert_eq!(pulses[0], 10, "record {i}: the train starts at 10 ms");
        let span = pulses[pulses.len() - 1] - pulses[0];
        assert!(span <= 300, "record {i}: train of {span} ms");
        let ipis: Vec<usize> = pulses.windows(2).map(|w| w[1] - w[0]).collect();
        if (i + 1) % 10 == 0 {
            assert_eq!(r.kind, "constant 40 Hz");
            assert_eq!(pulses.len(), 13);
            assert!(ipis.iter().all(|&d| d == 25));
        } else {
            assert_eq!(r.kind, "random");
            min_ipi = min_ipi.min(*ipis.iter().min().expect("pulses"));
            max_ipi = max_ipi.max(*ipis.iter().max().expect("pulses"));
        }
        // The muscle rests until the first pulse's force appears (8 ms later): only noise.
        assert!(r.force[..18].iter().all(|f| f.abs() < 0.05), "record {i}");
    }
    assert!(min_ipi >= 1 && max_ipi <= 70, "IPIs {min_ipi}..{max_ipi}");
    assert!(
        min_ipi <= 2 && max_ipi >= 65,
        "IPIs should span the range: {min_ipi}..{max_ipi}"
    );
}

/// `record` with the same seed writes byte-identical data sets that follow the thesis
/// protocol; another seed gives another data set.
#[test]
fn record_is_deterministic_and_follows_the_protocol() {
    let (a, b, c) = (
        Scratch::new("rec-a"),
        Scratch::new("rec-b"),
        Scratch::new("rec-c"),
    );
    for dir in [&a, &b] {
        run_ok(&[
            "record",
            "--preset",
            "fast",
            "--seed",
            "1",
            "--out",
            dir.path().to_str().expect("utf-8"),
        ]);
    }
    run_ok(&[
        "record",
        "--preset",
        "fast",
        "--seed",
        "2",
        "--out",
        c.path().to_str().expect("utf-8"),
    ]);
    let mut names: Vec<_> = fs::read_dir(a.path())
        .expect("dir")
        .map(|e| e.expect("entry").file_name())
        .collect();
    names.sort();
    assert_eq!(names.len(), 61);
    for name in &names {
        let x = fs::read(a.path().join(name)).expect("read");
        let y = fs::read(b.path().join(name)).expect("read");
        assert!(x == y, "{name:?} differs between two runs with seed 1");
    }
    assert_ne!(
        fs::read(a.join("record_000.csv")).ok(),
        fs::read(c.join("record_000.csv")).ok()
    );
    check_thesis_dataset(a.path(), Preset::Fast, 60, 590);
}

#[test]
fn record_slow_thesis_numbers() {
    let dir = Scratch::new("rec-slow");
    run_ok(&[
        "record",
        "--preset",
        "slow",
        "--seed",
        "3",
        "--out",
        dir.path().to_str().expect("utf-8"),
    ]);
    check_thesis_dataset(dir.path(), Preset::Slow, 84, 600);
}

/// With no noise and no offset the stored force times `scale_n` is the muscle's force
/// for the stored pulses, each record from rest.
#[test]
fn record_stores_the_normalised_model_force() {
    let dir = Scratch::new("rec-clean");
    let p = dir.path().to_str().expect("utf-8");
    run_ok(&[
        "record",
        "--preset",
        "slow",
        "--records",
        "4",
        "--train-records",
        "2",
        "--noise-std-n",
        "0",
        "--offset-n",
        "0",
        "--out",
        p,
    ]);
    let ds = DataSet::read(dir.path()).expect("read");
    assert_eq!(ds.header.offset_n, 0.0);
    for r in &ds.records {
        let mut m = Muscle::new(MuscleConfig::preset(Preset::Slow)).expect("valid");
        let f = simulate(&mut m, &r.pulse, Pulse::SUPRAMAXIMAL);
        for (x, y) in r.force.iter().zip(&f) {
            assert!((x * ds.header.scale_n - y).abs() <= 1e-9 * ds.header.scale_n);
        }
    }
}

/// The rich protocol spreads constant trains over 5-100 Hz and adds doublet-led trains.
#[test]
fn record_rich_protocol() {
    let dir = Scratch::new("rec-rich");
    run_ok(&[
        "record",
        "--preset",
        "fast",
        "--protocol",
        "rich",
        "--out",
        dir.path().to_str().expect("utf-8"),
    ]);
    let ds = DataSet::read(dir.path()).expect("read");
    let freqs: Vec<f64> = ds
        .records
        .iter()
        .filter_map(|r| {
            r.kind
                .strip_prefix("constant ")?
                .strip_suffix(" Hz")?
                .parse()
                .ok()
        })
        .collect();
    assert!(freqs.len() >= 20);
    let (lo, hi) = freqs
        .iter()
        .fold((f64::MAX, 0.0f64), |(l, h), &f| (l.min(f), h.max(f)));
    assert!(lo < 7.0 && hi > 80.0, "{lo}..{hi}");
    let doublets = ds
        .records
        .iter()
        .filter(|r| r.kind.starts_with("doublet"))
        .count();
    assert!(doublets >= 15);
    for r in ds.records.iter().filter(|r| r.kind.starts_with("doublet")) {
        let pulses: Vec<usize> = (0..r.len()).filter(|&k| r.pulse[k]).collect();
        assert!((2..=10).contains(&(pulses[1] - pulses[0])), "{}", r.kind);
    }
}

/// `plot` writes a PNG; `record` refuses a non-empty directory unless --force.
#[test]
fn plot_and_overwrite() {
    let dir = Scratch::new("plot");
    let data = dir.join("data");
    let d = data.to_str().expect("utf-8");
    run_ok(&[
        "record",
        "--preset",
        "slow",
        "--records",
        "12",
        "--train-records",
        "6",
        "--out",
        d,
    ]);
    let out = run(&[
        "record",
        "--preset",
        "slow",
        "--records",
        "12",
        "--train-records",
        "6",
        "--out",
        d,
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("not empty"));
    run_ok(&[
        "record",
        "--preset",
        "slow",
        "--records",
        "12",
        "--train-records",
        "6",
        "--out",
        d,
        "--force",
    ]);
    let png = dir.join("slow.png");
    run_ok(&[
        "plot",
        "--data",
        d,
        "--out",
        png.to_str().expect("utf-8"),
        "--records",
        "0,1,2,9",
    ]);
    let bytes = fs::read(&png).expect("png");
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    // The same figure as a vector image, by the extension.
    let svg = dir.join("slow.svg");
    run_ok(&["plot", "--data", d, "--out", svg.to_str().expect("utf-8")]);
    let text = fs::read_to_string(&svg).expect("svg");
    assert!(
        text.starts_with("<svg") && text.contains("</svg>"),
        "{}",
        &text[..80]
    );
}

/// Each bad invocation: non-zero exit, an error naming the problem on stderr, nothing
/// on stdout, and no output directory or file.
#[test]
fn bad_flags_fail_clearly_and_write_nothing() {
    let dir = Scratch::new("bad");
    let out = dir.join("out");
    let o = out.to_str().expect("utf-8");
    let png = dir.join("x.png");
    let p = png.to_str().expect("utf-8");
    let sim = ["simulate", "--preset", "fast", "--duration-ms", "100"];
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            [&sim[..], &["--set", "foo=1", "--pulses", "0"]].concat(),
            "unknown parameter `foo`",
        ),
        (
            [&sim[..], &["--set", "tau1=-0.01", "--pulses", "0"]].concat(),
            "`tau1` = -0.01 is out of range: must be > 0",
        ),
        (
            [&sim[..], &["--set", "tauc=0", "--pulses", "0"]].concat(),
            "`tauc` = 0 is out of range",
        ),
        (
            [&sim[..], &["--set", "tau1=NaN", "--pulses", "0"]].concat(),
            "not a finite number",
        ),
        (
            [&sim[..], &["--set", "tau1", "--pulses", "0"]].concat(),
            "is not NAME=VALUE",
        ),
        ([&sim[..], &["--pulses", ""]].concat(), "--pulses"),
        (
            [&sim[..], &["--pulses", "5,3"]].concat(),
            "must strictly increase",
        ),
        (
            [&sim[..], &["--pulses", "0.5"]].concat(),
            "not a multiple of the 1 ms sample period",
        ),
        (
            [&sim[..], &["--pulses", "100"]].concat(),
            "not before the end",
        ),
        (
            [&sim[..], &["--pulses", "NaN"]].concat(),
            "not a finite time",
        ),
        (
            [&sim[..], &["--freq", "NaN", "--train-ms", "50"]].concat(),
            "frequency NaN Hz",
        ),
        (
            [&sim[..], &["--freq", "-5", "--train-ms", "50"]].concat(),
            "frequency -5 Hz",
        ),
        ([&sim[..], &["--freq", "40"]].concat(), "--train-ms"),
        (
            [&sim[..], &["--pulses", "0", "--emd-ms", "-1"]].concat(),
            "`emd` = -0.001 is out of range",
        ),
        (
            [&sim[..], &["--pulses", "0", "--emd-ms", "NaN"]].concat(),
            "`emd` = NaN is not a finite number",
        ),
        (
            [&sim[..], &["--pulses", "0,50", "--repeat-ms", "20"]].concat(),
            "--repeat-ms 20",
        ),
        (
            [&sim[..], &["--pulses", "0", "--noise-std-n", "1"]].concat(),
            "add --measured",
        ),
        (
            vec![
                "simulate",
                "--preset",
                "medium",
                "--pulses",
                "0",
                "--duration-ms",
                "10",
            ],
            "invalid value 'medium'",
        ),
        (
            vec!["simulate", "--preset", "fast", "--pulses", "0"],
            "--duration-ms",
        ),
        (
            vec![
                "record",
                "--preset",
                "fast",
                "--out",
                o,
                "--ipi-min-ms",
                "80",
            ],
            "IPI range inverted: min 80 ms > max 70 ms",
        ),
        (
            vec![
                "record",
                "--preset",
                "fast",
                "--out",
                o,
                "--train-records",
                "0",
            ],
            "--train-records",
        ),
        (
            vec!["record", "--preset", "fast", "--out", o, "--records", "1"],
            "--records",
        ),
        (
            vec![
                "record",
                "--preset",
                "fast",
                "--out",
                o,
                "--record-ms",
                "200",
            ],
            "--record-ms",
        ),
        (
            vec!["record", "--preset", "fast", "--out", o, "--set", "km=-1"],
            "`km` = -1 is out of range",
        ),
        (
            vec![
                "record",
                "--preset",
                "fast",
                "--out",
                o,
                "--noise-std-n",
                "-1",
            ],
            "`noise_std` = -1",
        ),
        (
            vec!["record", "--preset", "fast", "--out", o, "--ts-ms", "2"],
            "--ts-ms",
        ),
        (
            vec![
                "record",
                "--preset",
                "fast",
                "--out",
                o,
                "--protocol",
                "rich",
                "--rich-min-hz",
                "50",
                "--rich-max-hz",
                "10",
            ],
            "frequency range inverted",
        ),
        (
            vec![
                "record",
                "--preset",
                "fast",
                "--out",
                o,
                "--fatigue",
                "--set",
                "tau_fat=-3",
            ],
            "`tau_fat` = -3",
        ),
        (vec!["plot", "--data", o, "--out", p], "does not exist"),
    ];
    for (args, expected) in cases {
        let r = run(&args);
        let stderr = String::from_utf8_lossy(&r.stderr);
        assert!(!r.status.success(), "{args:?} succeeded");
        assert!(
            stderr.contains(expected),
            "{args:?}\n stderr: {stderr}\n want: {expected}"
        );
        assert!(r.stdout.is_empty(), "{args:?} wrote to stdout");
        assert!(!out.exists() && !png.exists(), "{args:?} wrote output");
    }
    // A bad record index or a non-PNG name is refused after reading a valid data set.
    run_ok(&[
        "record",
        "--preset",
        "fast",
        "--records",
        "3",
        "--train-records",
        "1",
        "--out",
        o,
    ]);
    for (args, expected) in [
        (
            vec!["plot", "--data", o, "--out", p, "--records", "0,7"],
            "record 7 does not exist",
        ),
        (
            vec![
                "plot",
                "--data",
                o,
                "--out",
                dir.join("x.jpg").to_str().expect("utf-8"),
            ],
            "must be a .png",
        ),
    ] {
        let r = run(&args);
        assert!(!r.status.success());
        assert!(
            String::from_utf8_lossy(&r.stderr).contains(expected),
            "{args:?}"
        );
        assert!(!png.exists() && !dir.join("x.jpg").exists());
    }
}
