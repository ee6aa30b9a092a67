//! Checks judged against the host's timing, apart from the functional tests: each measures
//! the host's own noise beside the run (`fes_testkit::noise`) and bounds what it checks by
//! what the host allowed, so a correct loop on a stalling host passes and a loop that
//! blocks or falls behind by itself fails.

use crate::rt_process::slow_consumer_run;

/// With slow and stopped consumers on its outputs, rt-core keeps its period: it misses no
/// more periods than the host's noise explains (a blocked publisher misses them all).
#[test]
fn the_loop_keeps_its_period_beside_slow_and_stopped_consumers() {
    let run = slow_consumer_run("slowconsumer-timing", true);
    let report = run.summary.rt_core.expect("timing report");
    let noise = run.noise.expect("noise measured");
    let allowed = noise.allowed_misses(report.ticks);
    eprintln!(
        "rt-core missed {} of {} periods (allowed {allowed}); {noise}",
        report.misses, report.ticks
    );
    assert!(
        report.misses <= allowed,
        "rt-core missed {} of {} periods, more than the host's noise explains ({allowed}); {noise}",
        report.misses,
        report.ticks
    );
}
