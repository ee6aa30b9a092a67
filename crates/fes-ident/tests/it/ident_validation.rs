//! The field's validation figures ([`fes_ident::ident::validation`]) against independent
//! truths: a hand calculation on a tiny case, and numpy's own correlations on a longer one
//! (the test runs `python3` with numpy, as `scripts/setup` installs it).

use std::process::Command;

use fes_ident::ident::validation::{RESID_LAGS, Z_99, fit_percent, resid, rrse};

/// y = 1, 2, 3, 4 and y_hat = 1, 2, 3, 5: ||y - y_hat|| = 1, ||y - mean|| = sqrt(5).
#[test]
fn fit_and_rrse_of_a_tiny_case_by_hand() {
    let y = [1.0, 2.0, 3.0, 4.0];
    let yh = [1.0, 2.0, 3.0, 5.0];
    let r = rrse(&y, &yh).unwrap();
    assert!((r - (1.0f64 / 5.0).sqrt()).abs() < 1e-15, "{r}");
    assert!((fit_percent(&y, &yh).unwrap() - 100.0 * (1.0 - 0.2f64.sqrt())).abs() < 1e-12);
    assert_eq!(fit_percent(&y, &y), Some(100.0));
    // The mean as the model: fit 0; a constant output has no defined fit.
    assert!(fit_percent(&y, &[2.5; 4]).unwrap().abs() < 1e-12);
    assert_eq!(rrse(&[1.0; 3], &[1.0, 2.0, 3.0]), None);
    assert_eq!(rrse(&y, &yh[..3]), None);
}

/// e(t) = u(t - 2) plus a little: the cross-correlation peaks at lag +2 (the residual
/// follows the input 2 samples later) and the autocorrelation of e at 0 is 1.
#[test]
fn resid_finds_an_input_left_in_the_residual_at_its_lag() {
    let n = 400;
    let u: Vec<f64> = (0..n)
        .map(|t| if (t * 7919 + 13) % 11 < 3 { 1.0 } else { 0.0 })
        .collect();
    let e: Vec<f64> = (0..n)
        .map(|t| if t >= 2 { u[t - 2] } else { 0.0 } + 0.01 * ((t * 37 % 17) as f64 - 8.0))
        .collect();
    let r = resid(&[(&e, &u)], RESID_LAGS).unwrap();
    assert!((r.autocorr[0] - 1.0).abs() < 1e-12);
    let peak = (0..r.xcorr.len())
        .max_by(|&a, &b| r.xcorr[a].abs().total_cmp(&r.xcorr[b].abs()))
        .unwrap();
    assert_eq!(peak as isize - RESID_LAGS as isize, 2);
    assert!(r.xcorr[peak] > 0.9);
    assert!((r.band - Z_99 / (n as f64).sqrt()).abs() < 1e-15);
    assert!(r.xcorr_outside >= 1);
}

/// The same formulas computed by numpy on two records (correlations within records only):
/// every autocorrelation and cross-correlation lag to 1e-12.
#[test]
fn resid_matches_numpy_on_two_records() {
    let mk = |n: usize, a: usize, b: usize| -> (Vec<f64>, Vec<f64>) {
        let u: Vec<f64> = (0..n).map(|t| ((t * a + 5) % 13) as f64 / 13.0).collect();
        let e: Vec<f64> = (0..n)
            .map(|t| ((t * b + 3) % 29) as f64 / 29.0 - 0.4 + 0.3 * u[t.saturating_sub(1)])
            .collect();
        (e, u)
    };
    let (e1, u1) = mk(300, 7, 11);
    let (e2, u2) = mk(170, 5, 19);
    let r = resid(&[(&e1, &u1), (&e2, &u2)], RESID_LAGS).unwrap();
    let dir = fes_testkit::Scratch::new("resid-numpy");
    let write = |name: &str, v: &[f64]| {
        let text: Vec<String> = v.iter().map(|x| format!("{x:e}")).collect();
        std::fs::write(dir.join(name), text.join("\n")).unwrap();
    };
    write("e1", &e1);
    write("u1", &u1);
    write("e2", &e2);
    write("u2", &u2);
    let script = r#"
import sys, numpy as np
d, K = sys.argv[1], int(sys.argv[2])
rec = [(np.loadtxt(f"{d}/e{i}"), np.loadtxt(f"{d}/u{i}")) for i in (1, 2)]
me = np.concatenate([e for e, _ in rec]).mean()
mu = np.concatenate([u for _, u in rec]).mean()
rec = [(e - me, u - mu) for e, u in rec]
def c(a, b, k):  # sum_t a(t) b(t + k), full cross-correlation of numpy
    full = np.correlate(b, a, mode="full")  # index k + len(a) - 1
    i = k + len(a) - 1
    return full[i] if 0 <= i < len(full) else 0.0
ee = sum(c(e, e, 0) for e, _ in rec)
uu = sum(c(u, u, 0) for _, u in rec)
ac = [sum(c(e, e, k) for e, _ in rec) / ee for k in range(0, K + 1)]
xc = [sum(c(u, e, k) for e, u in rec) / np.sqrt(ee * uu) for k in range(-K, K + 1)]
print(" ".join(repr(float(v)) for v in ac + xc))
"#;
    let out = Command::new("python3")
        .arg("-c")
        .arg(script)
        .arg(dir.path())
        .arg(RESID_LAGS.to_string())
        .output()
        .expect("python3 (scripts/setup installs it with numpy)");
    assert!(
        out.status.success(),
        "numpy check failed (scripts/setup installs numpy): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let numpy: Vec<f64> = String::from_utf8_lossy(&out.stdout)
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    let ours: Vec<f64> = r.autocorr.iter().chain(&r.xcorr).copied().collect();
    assert_eq!(numpy.len(), ours.len());
    for (i, (a, b)) in ours.iter().zip(&numpy).enumerate() {
        assert!((a - b).abs() < 1e-12, "lag index {i}: ours {a}, numpy {b}");
    }
}
