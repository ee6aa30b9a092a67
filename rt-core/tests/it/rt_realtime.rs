//! `enter_realtime` in both situations: with the rights (SCHED_FIFO, affinity and memory
//! locking verified independently through the kernel's own interfaces), and without them (a
//! missing core; no SCHED_FIFO rights in a child process), under both policies.
//!
//! Dropping the rights reliably, even as root: the child is this test binary re-executed
//! with RLIMIT_RTPRIO = 0 and CAP_SYS_NICE removed from its capability bounding set before
//! exec (see `rt_common::without_rt_rights`), so it comes out of exec without CAP_SYS_NICE.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use crate::rt_common;

use std::process::Command;

use fes_rt::rt::realtime::RtShortfall;
use fes_rt::rt::{MissingRightsPolicy, RtConfig, RtError, enter_realtime};

fn policy_and_priority() -> (i32, i32) {
    let mut policy = 0;
    let mut param = libc::sched_param { sched_priority: 0 };
    // SAFETY: valid out-pointers; pthread_self() is the calling thread.
    let rc = unsafe { libc::pthread_getschedparam(libc::pthread_self(), &mut policy, &mut param) };
    assert_eq!(rc, 0);
    (policy, param.sched_priority)
}

fn affinity() -> Vec<usize> {
    // SAFETY: a zeroed cpu_set_t is a valid empty set; pid 0 = the calling thread.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        assert_eq!(
            libc::sched_getaffinity(0, std::mem::size_of_val(&set), &mut set),
            0
        );
        (0..libc::CPU_SETSIZE as usize)
            .filter(|&c| libc::CPU_ISSET(c, &set))
            .collect()
    }
}

fn locked_kib() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status.lines().find(|l| l.starts_with("VmLck:")).unwrap();
    line.split_whitespace().nth(1).unwrap().parse().unwrap()
}

fn config(core: Option<usize>, policy: MissingRightsPolicy) -> RtConfig {
    RtConfig {
        priority: 30,
        core,
        on_missing_rights: policy,
        lock_memory: true,
        prefault_stack_bytes: 64 * 1024,
        cpu_dma_latency_us: None,
    }
}

#[test]
fn with_the_rights_the_thread_gets_sched_fifo_its_core_and_locked_memory() {
    let last_core = *affinity().last().unwrap();
    std::thread::spawn(move || {
        let status = enter_realtime(&RtConfig {
            cpu_dma_latency_us: Some(0),
            ..config(Some(last_core), MissingRightsPolicy::Refuse)
        })
        .unwrap();
        assert!(!status.is_degraded(), "{status}");
        assert_eq!(status.fifo_priority, Some(30));
        assert_eq!(status.core, Some(last_core));
        assert!(status.memory_locked);
        assert_eq!(policy_and_priority(), (libc::SCHED_FIFO, 30));
        assert_eq!(affinity(), vec![last_core]);
        assert!(locked_kib() > 0);
        // The PM QoS device reads back the system-wide limit in force: ours.
        assert_eq!(status.cpu_dma_latency_us, Some(0));
        let mut current = [0u8; 4];
        use std::io::Read;
        std::fs::File::open("/dev/cpu_dma_latency")
            .unwrap()
            .read_exact(&mut current)
            .unwrap();
        assert_eq!(i32::from_ne_bytes(current), 0);
        let line = status.to_string();
        assert!(line.starts_with("real-time: SCHED_FIFO 30, core"), "{line}");
        assert!(!line.contains('\n'));
    })
    .join()
    .unwrap();
}

#[test]
fn a_core_that_does_not_exist_is_a_shortfall_refused_or_tolerated() {
    std::thread::spawn(|| {
        let before = affinity();
        let status = enter_realtime(&config(Some(4000), MissingRightsPolicy::BestEffort)).unwrap();
        assert!(status.is_degraded());
        assert_eq!(
            status.shortfalls,
            vec![RtShortfall::CoreMissing {
                core: 4000,
                available: before.len()
            }]
        );
        assert_eq!(status.core, None);
        assert_eq!(affinity(), before, "not pinned");
        // Best effort still got SCHED_FIFO.
        assert_eq!(policy_and_priority(), (libc::SCHED_FIFO, 30));
        let line = status.to_string();
        assert!(
            line.contains("DEGRADED (best-effort): core 4000 does not exist here"),
            "{line}"
        );
        assert!(!line.contains('\n'));
    })
    .join()
    .unwrap();

    std::thread::spawn(|| {
        match enter_realtime(&config(Some(4000), MissingRightsPolicy::Refuse)) {
            Err(RtError::Refused(status)) => {
                assert!(status.to_string().contains("REFUSED"));
                assert_eq!(status.fifo_priority, None);
            }
            other => panic!("expected a refusal, got {other:?}"),
        }
        // The refused thread was put back to normal scheduling.
        assert_eq!(policy_and_priority().0, libc::SCHED_OTHER);
    })
    .join()
    .unwrap();
}

#[test]
fn invalid_settings_are_rejected_before_anything_changes() {
    let mut c = config(None, MissingRightsPolicy::BestEffort);
    c.priority = 0;
    assert!(matches!(enter_realtime(&c), Err(RtError::Config(_))));
    c.priority = 100;
    assert!(matches!(enter_realtime(&c), Err(RtError::Config(_))));
    c.priority = 50;
    c.prefault_stack_bytes = 64 << 20;
    assert!(matches!(enter_realtime(&c), Err(RtError::Config(_))));
}

const CHILD_ENV: &str = "RT_CORE_TEST_CHILD_WITHOUT_RIGHTS";

/// Helper run in a child process by the next test (ignored on its own).
#[test]
#[ignore = "helper: run by without_sched_fifo_rights_..., in a child without CAP_SYS_NICE"]
fn child_enter_realtime_without_rights() {
    if std::env::var_os(CHILD_ENV).is_none() {
        return;
    }
    for policy in [MissingRightsPolicy::Refuse, MissingRightsPolicy::BestEffort] {
        let result = std::thread::spawn(move || {
            let r = enter_realtime(&RtConfig {
                lock_memory: false,
                ..config(None, policy)
            });
            (r, policy_and_priority().0)
        })
        .join()
        .unwrap();
        match result {
            (Err(RtError::Refused(s)), p) => println!("CHILD {policy:?} refused policy={p}: {s}"),
            (Ok(s), p) => println!("CHILD {policy:?} ok policy={p}: {s}"),
            (Err(e), _) => println!("CHILD {policy:?} error: {e}"),
        }
    }
}

#[test]
fn without_sched_fifo_rights_it_refuses_or_runs_best_effort() {
    let mut cmd = Command::new(std::env::current_exe().unwrap());
    cmd.args([
        "--ignored",
        "--exact",
        "rt_realtime::child_enter_realtime_without_rights",
        "--nocapture",
        "--test-threads=1",
    ])
    .env(CHILD_ENV, "1");
    rt_common::without_rt_rights(&mut cmd);
    let out = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The test harness prints its own prefix on the first line: take each line from "CHILD".
    let lines: Vec<&str> = stdout
        .lines()
        .filter_map(|l| l.find("CHILD ").map(|i| &l[i..]))
        .collect();
    assert_eq!(lines.len(), 2, "{stdout}");
    let normal = format!("policy={}", libc::SCHED_OTHER);
    assert!(
        lines[0].starts_with("CHILD Refuse refused") && lines[0].contains(&normal),
        "{}",
        lines[0]
    );
    assert!(
        lines[0].contains("no SCHED_FIFO 30 (EPERM: needs CAP_SYS_NICE or RLIMIT_RTPRIO >= 30)"),
        "{}",
        lines[0]
    );
    assert!(
        lines[1].starts_with("CHILD BestEffort ok") && lines[1].contains(&normal),
        "{}",
        lines[1]
    );
    assert!(
        lines[1].contains("DEGRADED (best-effort): no SCHED_FIFO 30"),
        "{}",
        lines[1]
    );
    assert!(lines[1].contains("got: SCHED_OTHER"), "{}", lines[1]);
}
