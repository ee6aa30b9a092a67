//! The model file loader on any text: an error, or a model that is valid with stability
//! required and simulates from rest to a finite force (what "accepted" promises).
#![no_main]

use fes_model::model::file;
use fes_model::model::lmn::Stability;
use fes_model::model::simulate::simulate;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(lmn) = file::from_json_str(text, Stability::Require) else {
        return;
    };
    lmn.validate(Stability::Require)
        .expect("accepted means valid");
    let net = lmn.network().expect("an accepted model builds its network");
    let u: Vec<f64> = (0..300).map(|k| f64::from(u8::from(k % 13 == 0))).collect();
    let mut y = vec![0.0; u.len()];
    simulate(&net, &u, &mut y).expect("an accepted model simulates");
    assert!(y.iter().all(|v| v.is_finite()), "non-finite force");
});
