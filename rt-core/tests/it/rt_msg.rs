//! Message contracts: pinned layouts (a change must be deliberate and renamed `v2`), type
//! names, and validation tables.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use core::mem::{align_of, offset_of, size_of};

use fes_rt::msg::service::{TOPIC_STIM_TICK, service_name, validate_prefix};
use fes_rt::msg::*;

fn type_name<T: ZeroCopySend>() -> &'static str {
    // SAFETY: only reads the constant name string of the derive.
    unsafe { <T as ZeroCopySend>::type_name() }
}

#[test]
fn layouts_are_pinned() {
    assert_eq!((size_of::<Reference>(), align_of::<Reference>()), (40, 8));
    assert_eq!(offset_of!(Reference, force), 16);
    assert_eq!(offset_of!(Reference, flags), 32);

    assert_eq!(
        (size_of::<PreviewEdge>(), align_of::<PreviewEdge>()),
        (24, 8)
    );
    assert_eq!(
        (
            size_of::<ReferencePreview>(),
            align_of::<ReferencePreview>()
        ),
        (176, 8)
    );
    assert_eq!(offset_of!(ReferencePreview, ref_seq), 16);
    assert_eq!(offset_of!(ReferencePreview, len), 24);
    assert_eq!(offset_of!(ReferencePreview, edges), 32);

    assert_eq!((size_of::<StimTick>(), align_of::<StimTick>()), (104, 8));
    assert_eq!(offset_of!(StimTick, seq), 0);
    assert_eq!(offset_of!(StimTick, t_ns), 8);
    assert_eq!(offset_of!(StimTick, t_publish_ns), 24);
    assert_eq!(offset_of!(StimTick, reference), 40);
    assert_eq!(offset_of!(StimTick, phi), 80);
    assert_eq!(offset_of!(StimTick, amplitude_ua), 88);
    assert_eq!(offset_of!(StimTick, missed_periods), 92);
    assert_eq!(offset_of!(StimTick, width_us), 96);
    assert_eq!(offset_of!(StimTick, flags), 98);
    assert_eq!(offset_of!(StimTick, pulse), 100);
    assert_eq!(offset_of!(StimTick, channel), 101);

    assert_eq!(
        (size_of::<ForceSample>(), align_of::<ForceSample>()),
        (40, 8)
    );
    assert_eq!(offset_of!(ForceSample, force), 32);

    assert_eq!(
        (size_of::<DriverStatus>(), align_of::<DriverStatus>()),
        (80, 8)
    );
    assert_eq!(offset_of!(DriverStatus, watchdog_trips), 56);
    assert_eq!(offset_of!(DriverStatus, state), 62);
    assert_eq!(offset_of!(DriverStatus, command_seq), 64);
    assert_eq!(offset_of!(DriverStatus, command_result), 72);
    assert_eq!(offset_of!(DriverStatus, command_reason), 73);

    assert_eq!(size_of::<LatencySummary>(), 40);
    assert_eq!(
        (size_of::<TimingReport>(), align_of::<TimingReport>()),
        (272, 8)
    );
    assert_eq!(offset_of!(TimingReport, wake), 64);
    assert_eq!(offset_of!(TimingReport, input), 104);
    assert_eq!(offset_of!(TimingReport, ipc), 224);
    assert_eq!(offset_of!(TimingReport, source), 264);

    assert_eq!(
        (size_of::<PulseOutcome>(), align_of::<PulseOutcome>()),
        (40, 8)
    );
    assert_eq!(offset_of!(PulseOutcome, tick_seq), 16);
    assert_eq!(offset_of!(PulseOutcome, fate), 32);
}

#[test]
fn type_names_are_explicit_and_versioned() {
    assert_eq!(type_name::<Reference>(), "fes::Reference::v1");
    assert_eq!(type_name::<ReferencePreview>(), "fes::ReferencePreview::v1");
    assert_eq!(type_name::<PreviewEdge>(), "fes::PreviewEdge::v1");
    assert_eq!(type_name::<StimTick>(), "fes::StimTick::v2");
    assert_eq!(type_name::<ForceSample>(), "fes::ForceSample::v1");
    assert_eq!(type_name::<DriverStatus>(), "fes::DriverStatus::v3");
    assert_eq!(type_name::<TimingReport>(), "fes::TimingReport::v2");
    assert_eq!(type_name::<LatencySummary>(), "fes::LatencySummary::v1");
    assert_eq!(type_name::<PulseOutcome>(), "fes::PulseOutcome::v3");
}

/// A PulseOutcome from another process is validated like every message: its fate is one of
/// the seven, its sequence numbers are set, its reserved bytes are zero.
#[test]
fn pulse_outcome_validation() {
    let ok = PulseOutcome::new(1, 5, 7, 3, PulseFate::Refused);
    assert_eq!(ok.validate(), Ok(()));
    assert_eq!(ok.fate(), Ok(PulseFate::Refused));
    for fate in [
        PulseFate::Sent,
        PulseFate::Refused,
        PulseFate::NotArmed,
        PulseFate::NotWritten,
        PulseFate::Late,
        PulseFate::Applied,
        PulseFate::NotApplied,
    ] {
        assert_eq!(PulseFate::try_from(fate as u8), Ok(fate));
        assert_eq!(
            fate.is_confirmation(),
            matches!(fate, PulseFate::Applied | PulseFate::NotApplied)
        );
    }
    let bad = [
        PulseOutcome { seq: 0, ..ok },
        PulseOutcome { tick_seq: 0, ..ok },
        PulseOutcome { fate: 0, ..ok },
        PulseOutcome { fate: 8, ..ok },
        PulseOutcome {
            reserved: [0, 0, 1, 0, 0, 0, 0],
            ..ok
        },
    ];
    for b in bad {
        assert!(b.validate().is_err(), "{b:?}");
    }
}

fn tick() -> StimTick {
    StimTick {
        seq: 7,
        t_ns: 1_000_000,
        t_wake_ns: 1_020_000,
        t_publish_ns: 1_030_000,
        ref_seq: 3,
        reference: 0.5,
        u_cont: 0.4,
        energy: 0.2,
        model_force: 0.45,
        predicted_force: 0.5,
        phi: 0.3,
        amplitude_ua: 20_000,
        missed_periods: 0,
        width_us: 200,
        flags: 0,
        pulse: 1,
        channel: 0,
        min_gap_ticks: 0,
    }
}

/// One row of a validation table: a name, a mutation of the valid baseline, the verdict.
type Case<M> = (&'static str, fn(&mut M), Option<ValidationError>);

/// Applies each mutation to `base` and checks the verdict.
fn table<M: Contract>(base: M, cases: &[Case<M>]) {
    base.validate().expect("baseline is valid");
    for (name, mutate, expected) in cases {
        let mut m = base;
        mutate(&mut m);
        let got = m.validate();
        match expected {
            None => assert_eq!(got, Ok(()), "{name}"),
            Some(e) => assert_eq!(got, Err(*e), "{name}"),
        }
    }
}

fn preview() -> ReferencePreview {
    let edge = |t_ns, force| PreviewEdge {
        t_ns,
        force,
        max_rate_per_s: 50.0,
    };
    ReferencePreview::new(4, 100, 3, &[edge(200, 0.0), edge(500, 0.4), edge(820, 0.0)])
}

#[test]
fn reference_preview_validation_table() {
    use ValidationError::*;
    table(
        preview(),
        &[
            (
                "nothing announced",
                |p| *p = ReferencePreview::new(4, 100, 3, &[]),
                None,
            ),
            ("a step edge", |p| p.edges[1].max_rate_per_s = 0.0, None),
            ("seq 0", |p| p.seq = 0, Some(ZeroSequence)),
            ("ref_seq 0", |p| p.ref_seq = 0, Some(ZeroSequence)),
            (
                "len beyond the edges",
                |p| p.len = 7,
                Some(IntOutOfRange {
                    field: "len",
                    value: 7,
                    min: 0,
                    max: 6,
                }),
            ),
            (
                "an edge not after the issue time",
                |p| p.edges[0].t_ns = 100,
                Some(TimestampOrder {
                    earlier: "t_ns",
                    earlier_ns: 100,
                    later: "edges[i].t_ns",
                    later_ns: 100,
                }),
            ),
            (
                "edges out of order",
                |p| p.edges[2].t_ns = 400,
                Some(TimestampOrder {
                    earlier: "edges[i-1].t_ns",
                    earlier_ns: 500,
                    later: "edges[i].t_ns",
                    later_ns: 400,
                }),
            ),
            (
                "force above 1",
                |p| p.edges[1].force = 1.5,
                Some(OutOfRange {
                    field: "edges[].force",
                    value: 1.5,
                    min: 0.0,
                    max: 1.0,
                }),
            ),
            (
                "infinite rate",
                |p| p.edges[1].max_rate_per_s = f64::INFINITY,
                Some(NotFinite {
                    field: "edges[].max_rate_per_s",
                    value: f64::INFINITY,
                }),
            ),
            (
                "an unused edge not zero",
                |p| p.edges[4].force = 0.3,
                Some(Inconsistent("an unused preview edge is not zero")),
            ),
            (
                "an unused edge of -0.0",
                |p| p.edges[5].force = -0.0,
                Some(Inconsistent("an unused preview edge is not zero")),
            ),
            (
                "reserved bytes",
                |p| p.reserved = [0, 1, 0, 0],
                Some(ReservedNotZero { field: "reserved" }),
            ),
        ],
    );
}

#[test]
fn reference_validation_table() {
    use ValidationError::*;
    table(
        Reference::new(1, 10, 0.5),
        &[
            ("zero force", |r| r.force = 0.0, None),
            ("full force", |r| r.force = 1.0, None),
            ("stop flag", |r| r.flags = Reference::FLAG_STOP, None),
            ("ramp", |r| r.max_rate_per_s = 2.5, None),
            ("seq 0", |r| r.seq = 0, Some(ZeroSequence)),
            (
                "force above 1",
                |r| r.force = 1.01,
                Some(OutOfRange {
                    field: "force",
                    value: 1.01,
                    min: 0.0,
                    max: 1.0,
                }),
            ),
            (
                "negative force",
                |r| r.force = -0.1,
                Some(OutOfRange {
                    field: "force",
                    value: -0.1,
                    min: 0.0,
                    max: 1.0,
                }),
            ),
            (
                "infinite force",
                |r| r.force = f64::INFINITY,
                Some(NotFinite {
                    field: "force",
                    value: f64::INFINITY,
                }),
            ),
            (
                "negative rate",
                |r| r.max_rate_per_s = -1.0,
                Some(OutOfRange {
                    field: "max_rate_per_s",
                    value: -1.0,
                    min: 0.0,
                    max: Reference::MAX_RATE_PER_S,
                }),
            ),
            (
                "unknown flag",
                |r| r.flags = 0b110,
                Some(UnknownFlags {
                    field: "flags",
                    bits: 0b110,
                }),
            ),
            (
                "reserved",
                |r| r.reserved[3] = 1,
                Some(ReservedNotZero { field: "reserved" }),
            ),
        ],
    );
    // NaN is reported as not finite (NaN != NaN, so compare by variant).
    let mut r = Reference::new(1, 10, f64::NAN);
    assert!(matches!(
        r.validate(),
        Err(NotFinite { field: "force", .. })
    ));
    r.force = 0.5;
    assert!(r.validate().is_ok());
}

#[test]
fn stim_tick_validation_table() {
    use ValidationError::*;
    table(
        tick(),
        &[
            (
                "no pulse, zero amplitude and width",
                |t| {
                    t.pulse = 0;
                    t.amplitude_ua = 0;
                    t.width_us = 0;
                },
                None,
            ),
            (
                "overrun with flag",
                |t| {
                    t.missed_periods = 3;
                    t.flags = StimTick::FLAG_OVERRUN;
                },
                None,
            ),
            (
                "every known flag but final/fault",
                |t| {
                    t.flags = StimTick::KNOWN_FLAGS
                        & !(StimTick::FLAG_FINAL
                            | StimTick::FLAG_SOURCE_FAULT
                            | StimTick::FLAG_OVERRUN)
                },
                None,
            ),
            ("seq 0", |t| t.seq = 0, Some(ZeroSequence)),
            (
                "woke before deadline",
                |t| t.t_wake_ns = 999_999,
                Some(TimestampOrder {
                    earlier: "t_ns",
                    earlier_ns: 1_000_000,
                    later: "t_wake_ns",
                    later_ns: 999_999,
                }),
            ),
            (
                "published before wake",
                |t| t.t_publish_ns = 1_010_000,
                Some(TimestampOrder {
                    earlier: "t_wake_ns",
                    earlier_ns: 1_020_000,
                    later: "t_publish_ns",
                    later_ns: 1_010_000,
                }),
            ),
            (
                "pulse 2",
                |t| t.pulse = 2,
                Some(IntOutOfRange {
                    field: "pulse",
                    value: 2,
                    min: 0,
                    max: 1,
                }),
            ),
            (
                "channel 16",
                |t| t.channel = 16,
                Some(IntOutOfRange {
                    field: "channel",
                    value: 16,
                    min: 0,
                    max: 15,
                }),
            ),
            (
                "amplitude above ceiling",
                |t| t.amplitude_ua = 250_001,
                Some(IntOutOfRange {
                    field: "amplitude_ua",
                    value: 250_001,
                    min: 0,
                    max: 250_000,
                }),
            ),
            (
                "reference above 1",
                |t| t.reference = 1.5,
                Some(OutOfRange {
                    field: "reference",
                    value: 1.5,
                    min: 0.0,
                    max: 1.0,
                }),
            ),
            (
                "infinite phi",
                |t| t.phi = f64::NEG_INFINITY,
                Some(NotFinite {
                    field: "phi",
                    value: f64::NEG_INFINITY,
                }),
            ),
            (
                "pulse without amplitude",
                |t| t.amplitude_ua = 0,
                Some(Inconsistent("a pulse needs a non-zero amplitude and width")),
            ),
            (
                "pulse without width",
                |t| t.width_us = 0,
                Some(Inconsistent("a pulse needs a non-zero amplitude and width")),
            ),
            (
                "amplitude without pulse",
                |t| t.pulse = 0,
                Some(Inconsistent(
                    "amplitude and width must be 0 without a pulse",
                )),
            ),
            (
                "final tick fires",
                |t| t.flags = StimTick::FLAG_FINAL,
                Some(Inconsistent("the final tick fires a pulse")),
            ),
            (
                "faulted tick fires",
                |t| t.flags = StimTick::FLAG_SOURCE_FAULT,
                Some(Inconsistent("a faulted tick fires a pulse")),
            ),
            (
                "misses without flag",
                |t| t.missed_periods = 2,
                Some(Inconsistent(
                    "FLAG_OVERRUN must be set exactly when missed_periods > 0",
                )),
            ),
            (
                "flag without misses",
                |t| t.flags = StimTick::FLAG_OVERRUN,
                Some(Inconsistent(
                    "FLAG_OVERRUN must be set exactly when missed_periods > 0",
                )),
            ),
            (
                "unknown flag",
                |t| t.flags = 1 << 12,
                Some(UnknownFlags {
                    field: "flags",
                    bits: 1 << 12,
                }),
            ),
            (
                "the first flag not defined",
                |t| t.flags = 1 << 11,
                Some(UnknownFlags {
                    field: "flags",
                    bits: 1 << 11,
                }),
            ),
        ],
    );
}

#[test]
fn force_sample_validation_table() {
    use ValidationError::*;
    table(
        ForceSample {
            seq: 1,
            t_ns: 5,
            stim_seq: 0,
            force_n: 3.0,
            force: 0.3,
        },
        &[
            (
                "slightly negative (offset, noise)",
                |f| f.force = -0.05,
                None,
            ),
            ("seq 0", |f| f.seq = 0, Some(ZeroSequence)),
            (
                "garbage normalised force",
                |f| f.force = 2.5,
                Some(OutOfRange {
                    field: "force",
                    value: 2.5,
                    min: -1.0,
                    max: 2.0,
                }),
            ),
            (
                "garbage newtons",
                |f| f.force_n = -20_000.0,
                Some(OutOfRange {
                    field: "force_n",
                    value: -20_000.0,
                    min: -10_000.0,
                    max: 10_000.0,
                }),
            ),
        ],
    );
}

#[test]
fn driver_status_validation_table() {
    use ValidationError::*;
    let base = DriverStatus {
        seq: 1,
        t_ns: 1,
        ticks_received: 100,
        ticks_lost: 0,
        pulses_sent: 10,
        pulses_rejected: 0,
        can_tx_errors: 0,
        watchdog_trips: 0,
        fault_code: 0,
        state: DeviceState::Armed as u8,
        stimulator_state: DeviceState::Unknown as u8,
        command_seq: 0,
        command_result: 0,
        command_reason: 0,
        reserved: [0; 6],
    };
    table(
        base,
        &[
            (
                "fault state with EMCY code",
                |s| {
                    s.state = DeviceState::Fault as u8;
                    s.fault_code = 0x8130;
                },
                None,
            ),
            (
                "unknown state",
                |s| s.state = 9,
                Some(UnknownEnum {
                    field: "state",
                    value: 9,
                }),
            ),
            (
                "unknown stimulator state",
                |s| s.stimulator_state = 77,
                Some(UnknownEnum {
                    field: "stimulator_state",
                    value: 77,
                }),
            ),
            (
                "more pulses than ticks",
                |s| s.pulses_sent = 101,
                Some(Inconsistent("more pulses sent than StimTicks received")),
            ),
            (
                "an accepted command",
                |s| {
                    s.command_seq = 7;
                    s.command_result = CommandResult::Accepted as u8;
                },
                None,
            ),
            (
                "a refused command with its reason",
                |s| {
                    s.command_seq = 7;
                    s.command_result = CommandResult::Refused as u8;
                    s.command_reason = CommandRefusal::NoTicks as u8;
                },
                None,
            ),
            (
                "a result without a command",
                |s| s.command_result = CommandResult::Accepted as u8,
                Some(Inconsistent(
                    "command_seq, command_result and command_reason disagree",
                )),
            ),
            (
                "a command without a result",
                |s| s.command_seq = 3,
                Some(Inconsistent(
                    "command_seq, command_result and command_reason disagree",
                )),
            ),
            (
                "an accepted command with a reason",
                |s| {
                    s.command_seq = 3;
                    s.command_result = CommandResult::Accepted as u8;
                    s.command_reason = 2;
                },
                Some(Inconsistent(
                    "command_seq, command_result and command_reason disagree",
                )),
            ),
            (
                "an unknown refusal reason",
                |s| {
                    s.command_seq = 3;
                    s.command_result = CommandResult::Refused as u8;
                    s.command_reason = 200;
                },
                Some(UnknownEnum {
                    field: "command_reason",
                    value: 200,
                }),
            ),
            (
                "an unknown result",
                |s| {
                    s.command_seq = 3;
                    s.command_result = 3;
                },
                Some(Inconsistent(
                    "command_seq, command_result and command_reason disagree",
                )),
            ),
            (
                "reserved bytes set",
                |s| s.reserved[5] = 1,
                Some(ReservedNotZero { field: "reserved" }),
            ),
        ],
    );
    assert_eq!(base.state(), Ok(DeviceState::Armed));
    assert_eq!(base.command_ack(), Ok(CommandAck::None));
    for r in CommandRefusal::ALL {
        assert_eq!(CommandRefusal::try_from(r as u8), Ok(r));
    }
    for v in 0..=255u8 {
        let known = matches!(v, 0..=5 | 255);
        assert_eq!(DeviceState::try_from(v).is_ok(), known, "{v}");
    }
}

#[test]
fn timing_report_validation_table() {
    use ValidationError::*;
    let s = LatencySummary {
        count: 10,
        p50_ns: 5,
        p99_ns: 9,
        p999_ns: 9,
        max_ns: 12,
    };
    let base = TimingReport {
        seq: 1,
        t_ns: 1,
        ticks: 10,
        misses: 0,
        overruns: 0,
        queue_overflows: 0,
        hot_path_allocations: 0,
        rejected_inputs: 0,
        wake: s,
        input: s,
        compute: s,
        publish: s,
        ipc: LatencySummary::default(),
        source: TimingSource::RtCore as u8,
        flags: TimingReport::FLAG_FINAL,
        prescription: [0; 6],
    };
    table(
        base,
        &[
            (
                "misses and overruns",
                |r| {
                    r.misses = 100;
                    r.overruns = 1;
                },
                None,
            ),
            (
                "source 0",
                |r| r.source = 0,
                Some(UnknownEnum {
                    field: "source",
                    value: 0,
                }),
            ),
            (
                "unknown flag",
                |r| r.flags = 1 << 5,
                Some(UnknownFlags {
                    field: "flags",
                    bits: 1 << 5,
                }),
            ),
            (
                "overruns without misses",
                |r| r.overruns = 1,
                Some(Inconsistent("overruns exceed misses or ticks")),
            ),
            (
                "unordered wake percentiles",
                |r| r.wake.p99_ns = 3,
                Some(Inconsistent(
                    "wake percentiles not ordered (or non-zero with count 0)",
                )),
            ),
            (
                "ipc values without count",
                |r| r.ipc.max_ns = 1,
                Some(Inconsistent(
                    "ipc percentiles not ordered (or non-zero with count 0)",
                )),
            ),
        ],
    );
}

#[test]
fn service_names_compose_prefix_and_topic() {
    assert_eq!(
        service_name("fes", TOPIC_STIM_TICK).unwrap().as_str(),
        "fes/stim_tick"
    );
    assert_eq!(
        service_name("bench/a-1", "x").unwrap().as_str(),
        "bench/a-1/x"
    );
    for bad in ["", "/fes", "fes/", "a b", "ü", &"x".repeat(65)] {
        assert!(validate_prefix(bad).is_err(), "{bad:?}");
    }
}

/// The hand-made tick constructors give valid ticks: quiet (no pulse, no state) and firing.
#[test]
fn quiet_and_firing_ticks_are_valid_and_say_what_they_are() {
    let q = StimTick::quiet(5, 7_000_000);
    assert!(q.validate().is_ok(), "{:?}", q.validate());
    assert!(!q.fires() && q.amplitude_ua == 0 && q.width_us == 0 && q.flags == 0);
    assert_eq!(
        (q.t_ns, q.t_wake_ns, q.t_publish_ns),
        (7_000_000, 7_000_000, 7_000_000)
    );
    let f = q.firing(3, 20_000, 200);
    assert!(f.validate().is_ok(), "{:?}", f.validate());
    assert!(f.fires());
    assert_eq!((f.channel, f.amplitude_ua, f.width_us), (3, 20_000, 200));
    assert!(
        StimTick { pulse: 0, ..f }.validate().is_err(),
        "amplitude without a pulse"
    );
}

/// The commanding services have one publisher: a second one, from any process of the same
/// user, is refused when it is made, so only the supervisor sends
/// References and DriverCommands and only rt-core sends StimTicks.
#[test]
fn a_second_publisher_of_a_commanding_service_is_refused() {
    use fes_rt::msg::{DriverCommand, port};
    use fes_rt::rt::node::create_node;
    fn second_is_refused<M: Contract + std::fmt::Debug>(prefix: &str) {
        let node = create_node("test-publishers").unwrap();
        let first = port::publisher::<M>(&node, prefix);
        assert!(first.is_ok(), "{}: {:?}", M::TOPIC, first.err());
        let second = port::publisher::<M>(&node, prefix);
        assert!(
            matches!(second, Err(fes_rt::msg::PortError::Publisher { .. })),
            "{}: a second publisher was made",
            M::TOPIC
        );
    }
    let prefix = format!("t{}pubs", std::process::id());
    second_is_refused::<Reference>(&prefix);
    second_is_refused::<DriverCommand>(&prefix);
    second_is_refused::<StimTick>(&prefix);
}

/// A service squatted before the stack starts: another process of the same user creates
/// `reference` (or `driver_command`, or `stim_tick`) first, with room for four publishers.
/// iceoryx2 opens it for our one-publisher request without complaint, and the squatter
/// could then publish beside the supervisor; the stack's open reads the limit back and
/// refuses the service, naming it. Without the read-back, the open succeeds and a second
/// publisher is admitted.
#[test]
fn a_service_another_process_created_with_more_publishers_is_refused() {
    use fes_rt::msg::service::{ServiceError, open_pubsub};
    use fes_rt::msg::{DriverCommand, PortError, port};
    use fes_rt::rt::node::create_node;
    fn squatted_is_refused<M: Contract + std::fmt::Debug>(prefix: &str) {
        let squatter = create_node("test-squatter").unwrap();
        let name = service_name(prefix, M::TOPIC).unwrap();
        let service = squatter
            .service_builder(&name)
            .publish_subscribe::<M>()
            .enable_safe_overflow(true)
            .max_publishers(4)
            .max_subscribers(M::QOS.max_subscribers)
            .subscriber_max_buffer_size(M::QOS.subscriber_buffer)
            .history_size(M::QOS.history)
            .create()
            .unwrap();
        let _squatting = service.publisher_builder().create().unwrap();
        let node = create_node("test-stack").unwrap();
        let opened = open_pubsub::<M>(&node, prefix);
        assert!(
            matches!(
                opened,
                Err(ServiceError::Foreign {
                    found: 4,
                    expected: 1,
                    ..
                })
            ),
            "{}: {:?}",
            M::TOPIC,
            opened.as_ref().err()
        );
        let publisher = port::publisher::<M>(&node, prefix);
        assert!(
            matches!(
                publisher,
                Err(PortError::Service(ServiceError::Foreign { .. }))
            ),
            "{}: the stack made its publisher on a squatted service",
            M::TOPIC
        );
        let e = publisher.err().unwrap().to_string();
        assert!(e.contains(M::TOPIC) && e.contains("another process"), "{e}");
    }
    let prefix = format!("t{}squat", std::process::id());
    squatted_is_refused::<Reference>(&prefix);
    squatted_is_refused::<DriverCommand>(&prefix);
    squatted_is_refused::<StimTick>(&prefix);
}
