//! The data-set record reader on any bytes: an error, or columns that are consistent
//! (equal lengths, at least two samples, time increasing from >= 0, finite force).
#![no_main]

use std::path::Path;

use fes_dataset::parse_record_csv;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(c) = parse_record_csv(Path::new("r.csv"), data, 1e-3) {
        let (t, p, f) = (&c.t_ms, &c.pulse, &c.force);
        assert!(t.len() >= 2 && t.len() == p.len() && t.len() == f.len());
        assert!(c.decided.as_ref().is_none_or(|d| d.len() == t.len()));
        assert!(t[0] >= 0.0 && t.windows(2).all(|w| w[1] > w[0]));
        assert!(f.iter().all(|x| x.is_finite()));
    }
});
