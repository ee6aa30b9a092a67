//! The testkit (crates/fes-testkit) checked here, in the system tests' binary, so that
//! the crate adds no test binary of its own (docs/architecture.md, "Tests").

mod scratch {
    use std::path::PathBuf;

    use fes_testkit::Scratch;

    #[test]
    fn removed_after_a_passing_test_and_unique() {
        let a = Scratch::new("unit");
        let b = Scratch::new("unit");
        assert_ne!(a.path(), b.path());
        assert!(a.path().is_dir());
        std::fs::write(a.join("f"), b"x").unwrap_or_else(|e| panic!("{e}"));
        let p = a.path().to_path_buf();
        drop(a);
        assert!(!p.exists());
    }

    #[test]
    fn kept_when_the_test_panics() {
        let path = std::thread::spawn(|| {
            let s = Scratch::new("unit-panic");
            let p = s.path().to_path_buf();
            std::panic::panic_any(p);
        })
        .join()
        .err()
        .and_then(|e| e.downcast::<PathBuf>().ok())
        .map(|p| *p);
        let Some(path) = path else {
            panic!("the thread did not panic with its path")
        };
        assert!(path.is_dir(), "{} was removed", path.display());
        let _ = std::fs::remove_dir_all(&path);
    }
}

mod noise {
    use fes_testkit::noise::{HostNoise, measure};

    #[test]
    fn the_bound_follows_the_probe() {
        let quiet = HostNoise {
            periods: 1000,
            ..HostNoise::default()
        };
        assert_eq!(quiet.allowed_misses(1000), 20);
        assert!(quiet.is_quiet());
        let noisy = HostNoise {
            periods: 1000,
            missed: 300,
            late_1ms: 20,
            ..HostNoise::default()
        };
        assert_eq!(noisy.allowed_misses(1000), 620);
        assert!(!noisy.is_quiet());
        // A blocked loop misses nearly everything: caught unless the host missed half.
        assert!(noisy.allowed_misses(1000) < 990);
    }

    #[test]
    fn a_probe_counts_the_periods_of_its_run() {
        let n = measure(1, 0.2);
        // 200 periods, give or take what a loaded host takes away at either end.
        assert!((150..=260).contains(&n.periods), "{n}");
        assert!(n.missed <= n.periods, "{n}");
    }
}
