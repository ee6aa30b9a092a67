//! Reference profiles: constant, steps, ramps, and the cardiac-assist square wave of
//! thesis 1.1 ("square-wave contractions synchronised to a heart rate of 60-200
//! beats/min with a duty cycle and an amplitude set by the outer loop").
//!
//! A profile is a function of time to a [`Setpoint`]: the force to head for and the rate
//! to get there at. The supervisor publishes the setpoint as a `Reference` and rt-core
//! ramps its target at that rate, so a ramp profile is exact at 1 ms resolution although
//! references are published every few milliseconds. Time is passed in (ns of
//! CLOCK_MONOTONIC); nothing here reads a clock.

use serde::{Deserialize, Serialize};

use fes_rt::msg::PreviewEdge;

use crate::limits::{ReferenceLimits, Rejection};

/// Heart-rate range of the cardiac profile, beats per minute (thesis 1.1: 1-3.3 Hz).
pub const HEART_RATE_BPM: (f64, f64) = (60.0, 200.0);
/// Duty-cycle range of the cardiac profile (fraction of the beat that contracts).
pub const DUTY: (f64, f64) = (0.05, 0.95);
/// Default rest before a cardiac profile's first contraction, ms ([`CardiacSpec::start_rest_ms`]).
pub const DEFAULT_START_REST_MS: f64 = 200.0;
/// Longest rest before a cardiac profile's first contraction, ms.
pub const MAX_START_REST_MS: f64 = 2000.0;
/// Most steps or ramp points in one profile.
pub const MAX_POINTS: usize = 1000;

/// One level of a [`ProfileSpec::Steps`] profile.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Step {
    /// Level, normalised force.
    pub force: f64,
    /// How long the level is held, s (the ramp towards it is part of the hold).
    pub hold_s: f64,
}

/// One corner of a [`ProfileSpec::Ramps`] profile.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RampPoint {
    /// Time from the start of the profile, s (the first point is at 0).
    pub t_s: f64,
    /// Force at that time, normalised.
    pub force: f64,
}

/// The cardiac-assist profile (thesis 1.1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CardiacSpec {
    /// Heart rate, beats per minute, in [60, 200].
    pub bpm: f64,
    /// Fraction of each beat spent contracting, in [0.05, 0.95].
    pub duty: f64,
    /// Target contraction amplitude, normalised force (the outer loop's target).
    pub amplitude: f64,
    /// Rate of the square wave's edges, normalised force per second; default: the
    /// configured rate limit (the steepest edge allowed).
    #[serde(default)]
    pub edge_rate_per_s: Option<f64>,
    /// Switch the outer loop on or off with this profile; absent: leave it as it is.
    #[serde(default)]
    pub outer_loop: Option<bool>,
    /// Rest before the first contraction, ms, in [0, [`MAX_START_REST_MS`]]; absent:
    /// [`DEFAULT_START_REST_MS`]. The first onset is announced in the reference preview from the
    /// start, so rt-core's planner gets this long to plan the first contraction, as it gets
    /// the rest phase to plan every later one (with no rest the first contraction is seen
    /// only at its onset, and its first pulses are decided before the plan is complete).
    /// Applies when the profile starts; a retune of a running profile ignores it.
    #[serde(default)]
    pub start_rest_ms: Option<f64>,
}

impl CardiacSpec {
    /// Beat period, ns.
    pub fn period_ns(&self) -> u64 {
        (60.0e9 / self.bpm).round() as u64
    }

    /// Contraction (on-phase) length, ns.
    pub fn on_ns(&self) -> u64 {
        (self.duty * 60.0e9 / self.bpm).round() as u64
    }

    /// Rest before the first contraction, ns.
    pub fn start_rest_ns(&self) -> u64 {
        (self.start_rest_ms.unwrap_or(DEFAULT_START_REST_MS) * 1e6).round() as u64
    }
}

/// A reference profile as the operator gives it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ProfileSpec {
    /// Hold `force`, reached at `rate_per_s` (default: the configured default rate).
    Constant {
        /// Level, normalised force.
        force: f64,
        /// Ramp rate towards it, /s.
        #[serde(default)]
        rate_per_s: Option<f64>,
    },
    /// Piecewise-constant levels, each reached at `rate_per_s`.
    Steps {
        /// The levels in order.
        steps: Vec<Step>,
        /// Start again after the last step (else hold the last level).
        #[serde(default)]
        repeat: bool,
        /// Ramp rate between levels, /s (default: the configured default rate).
        #[serde(default)]
        rate_per_s: Option<f64>,
    },
    /// Piecewise-linear through the points; every slope must respect the rate limit.
    Ramps {
        /// Corners; the first at t = 0, times increasing.
        points: Vec<RampPoint>,
        /// Start again after the last point (the last force must equal the first).
        #[serde(default)]
        repeat: bool,
    },
    /// Square-wave contractions synchronised to a heart rate (thesis 1.1).
    Cardiac(CardiacSpec),
}

/// What the reference should do now.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Setpoint {
    /// Force to head for, normalised.
    pub force: f64,
    /// Rate to head for it at, normalised force per second (> 0).
    pub rate_per_s: f64,
}

/// One beat of the cardiac profile, as it was run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Beat {
    /// 0, 1, 2, ... from the start of the profile.
    pub index: u64,
    /// Start of the beat (rising edge begins), ns.
    pub start_ns: u64,
    /// Beat period, ns (60 / bpm).
    pub period_ns: u64,
    /// Contraction length, ns (duty x period).
    pub on_ns: u64,
    /// Heart rate of this beat, beats per minute.
    pub bpm: f64,
    /// The operator's target amplitude, normalised force.
    pub target: f64,
    /// The amplitude the reference had in this beat (target + outer-loop correction).
    pub amplitude: f64,
}

impl Beat {
    /// End of the beat, ns.
    pub fn end_ns(&self) -> u64 {
        self.start_ns + self.period_ns
    }
}

impl ProfileSpec {
    /// Checks the profile against the limits; the error says what is wrong.
    pub fn validate(&self, limits: &ReferenceLimits) -> Result<(), Rejection> {
        match self {
            ProfileSpec::Constant { force, rate_per_s } => {
                limits.check_force("force", *force)?;
                if let Some(r) = rate_per_s {
                    limits.check_rate("rate", *r)?;
                }
            }
            ProfileSpec::Steps {
                steps, rate_per_s, ..
            } => {
                count("steps", steps.len(), 1)?;
                for (i, s) in steps.iter().enumerate() {
                    limits.check_force(&format!("steps[{i}].force"), s.force)?;
                    ReferenceLimits::check_duration(&format!("steps[{i}].hold_s"), s.hold_s)?;
                }
                if let Some(r) = rate_per_s {
                    limits.check_rate("rate", *r)?;
                }
            }
            ProfileSpec::Ramps { points, repeat } => {
                count("points", points.len(), 2)?;
                for (i, p) in points.iter().enumerate() {
                    limits.check_force(&format!("points[{i}].force"), p.force)?;
                    if !p.t_s.is_finite() {
                        return Err(Rejection::NotFinite {
                            what: format!("points[{i}].t_s"),
                            value: p.t_s,
                        });
                    }
                }
                if points[0].t_s != 0.0 {
                    return Err(Rejection::Outside {
                        what: "points[0].t_s".into(),
                        value: points[0].t_s,
                        unit: " s",
                        allowed: "[0, 0]".into(),
                        why: " (the first point must be at t = 0)",
                    });
                }
                for (i, w) in points.windows(2).enumerate() {
                    let dt = w[1].t_s - w[0].t_s;
                    if dt <= 0.0 {
                        return Err(Rejection::NotIncreasing {
                            what: format!("points[{}].t_s", i + 1),
                            value: w[1].t_s,
                            previous: w[0].t_s,
                        });
                    }
                    ReferenceLimits::check_duration(&format!("points[{}].t_s", i + 1), w[1].t_s)?;
                    let slope = (w[1].force - w[0].force).abs() / dt;
                    if slope > limits.max_rate_per_s {
                        return Err(Rejection::TooFast {
                            what: format!("ramp from t = {} s to {} s: slope", w[0].t_s, w[1].t_s),
                            rate_per_s: slope,
                            max_per_s: limits.max_rate_per_s,
                        });
                    }
                }
                let (first, last) = (points[0], points[points.len() - 1]);
                if *repeat && first.force != last.force {
                    return Err(Rejection::RepeatGap {
                        first: first.force,
                        last: last.force,
                    });
                }
            }
            ProfileSpec::Cardiac(c) => c.validate(limits)?,
        }
        Ok(())
    }

    /// Short description for status and logs.
    pub fn describe(&self) -> String {
        match self {
            ProfileSpec::Constant { force, .. } => format!("constant {force}"),
            ProfileSpec::Steps { steps, repeat, .. } => format!(
                "steps ({} levels{})",
                steps.len(),
                if *repeat { ", repeating" } else { "" }
            ),
            ProfileSpec::Ramps { points, repeat } => format!(
                "ramps ({} points{})",
                points.len(),
                if *repeat { ", repeating" } else { "" }
            ),
            ProfileSpec::Cardiac(c) => format!(
                "cardiac {} beats/min, duty {}, amplitude {}",
                c.bpm, c.duty, c.amplitude
            ),
        }
    }
}

fn count(what: &str, n: usize, min: usize) -> Result<(), Rejection> {
    if n < min || n > MAX_POINTS {
        return Err(Rejection::Outside {
            what: format!("number of {what}"),
            value: n as f64,
            unit: "",
            allowed: format!("{min}..={MAX_POINTS}"),
            why: "",
        });
    }
    Ok(())
}

impl CardiacSpec {
    /// The edge rate in use under `limits`.
    pub fn edge_rate(&self, limits: &ReferenceLimits) -> f64 {
        self.edge_rate_per_s.unwrap_or(limits.max_rate_per_s)
    }

    /// Checks heart rate, duty, amplitude and edge rate; the edges must fit into both
    /// phases of the beat.
    pub fn validate(&self, limits: &ReferenceLimits) -> Result<(), Rejection> {
        let (lo, hi) = HEART_RATE_BPM;
        if !self.bpm.is_finite() || !(lo..=hi).contains(&self.bpm) {
            return Err(Rejection::Outside {
                what: "heart rate".into(),
                value: self.bpm,
                unit: " beats/min",
                allowed: format!("[{lo}, {hi}]"),
                why: " (thesis 1.1: 1-3.3 Hz)",
            });
        }
        let (lo, hi) = DUTY;
        if !self.duty.is_finite() || !(lo..=hi).contains(&self.duty) {
            return Err(Rejection::Outside {
                what: "duty".into(),
                value: self.duty,
                unit: "",
                allowed: format!("[{lo}, {hi}]"),
                why: "",
            });
        }
        limits.check_force("amplitude", self.amplitude)?;
        if let Some(rest) = self.start_rest_ms
            && (!rest.is_finite() || !(0.0..=MAX_START_REST_MS).contains(&rest))
        {
            return Err(Rejection::Outside {
                what: "rest before the first contraction".into(),
                value: rest,
                unit: " ms",
                allowed: format!("[0, {MAX_START_REST_MS}]"),
                why: "",
            });
        }
        let rate = self.edge_rate(limits);
        limits.check_rate("edge rate", rate)?;
        let edge_s = self.amplitude / rate;
        let on_s = self.on_ns() as f64 * 1e-9;
        let off_s = (self.period_ns() - self.on_ns()) as f64 * 1e-9;
        if edge_s > on_s.min(off_s) {
            return Err(Rejection::EdgeTooLong {
                amplitude: self.amplitude,
                rate_per_s: rate,
                edge_ms: edge_s * 1e3,
                phase: if on_s <= off_s { "contraction" } else { "rest" },
                phase_ms: on_s.min(off_s) * 1e3,
            });
        }
        Ok(())
    }
}

/// Runs a [`ProfileSpec`] from a start time.
#[derive(Debug, Clone, PartialEq)]
pub struct ProfileRunner {
    spec: ProfileSpec,
    limits: ReferenceLimits,
    start_ns: u64,
    cardiac: Option<CardiacRun>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct CardiacRun {
    /// Parameters of the running beat.
    current: CardiacSpec,
    /// Parameters that take over at the next beat.
    pending: Option<CardiacSpec>,
    /// The running beat.
    beat: Beat,
    /// Amplitude the next beat will use (the outer loop's latest output).
    next_amplitude: f64,
}

impl CardiacRun {
    /// Advances to `now_ns`, starting the beats due on the way (with the pending
    /// parameters and the next amplitude) and appending their boundaries to `events`;
    /// returns the setpoint at `now_ns`: the beat's amplitude while it contracts, else 0.
    fn advance(
        &mut self,
        now_ns: u64,
        limits: &ReferenceLimits,
        events: &mut Vec<ProfileEvent>,
    ) -> Setpoint {
        while now_ns >= self.beat.end_ns() {
            events.push(ProfileEvent::BeatEnded(self.beat));
            if let Some(p) = self.pending.take() {
                self.current = p;
            }
            let c = self.current;
            self.beat = Beat {
                index: self.beat.index + 1,
                start_ns: self.beat.end_ns(),
                period_ns: c.period_ns(),
                on_ns: c.on_ns(),
                bpm: c.bpm,
                target: c.amplitude,
                amplitude: self.next_amplitude,
            };
            events.push(ProfileEvent::BeatStarted(self.beat));
        }
        let rate = self.current.edge_rate(limits);
        // Before the first beat (the start rest): rest.
        if (self.beat.start_ns..self.beat.start_ns + self.beat.on_ns).contains(&now_ns) {
            Setpoint {
                force: self.beat.amplitude,
                rate_per_s: rate,
            }
        } else {
            Setpoint {
                force: 0.0,
                rate_per_s: rate,
            }
        }
    }
}

/// The setpoint of a steps profile `t_s` s after its start (`repeat`: over again after the
/// last step), every change at `rate_per_s`.
fn steps_setpoint(steps: &[Step], repeat: bool, rate_per_s: f64, t_s: f64) -> Setpoint {
    let total: f64 = steps.iter().map(|s| s.hold_s).sum();
    let mut t = t_s;
    if repeat {
        t %= total;
    }
    let mut force = steps[steps.len() - 1].force;
    let mut edge = 0.0;
    for s in steps {
        edge += s.hold_s;
        if t < edge {
            force = s.force;
            break;
        }
    }
    Setpoint { force, rate_per_s }
}

/// The setpoint of a ramps profile `t_s` s after its start (`repeat`: over again after the
/// last point): the end of the running segment at its slope (`default_rate_per_s` for a
/// flat one).
fn ramps_setpoint(
    points: &[RampPoint],
    repeat: bool,
    default_rate_per_s: f64,
    t_s: f64,
) -> Setpoint {
    let total = points[points.len() - 1].t_s;
    let mut t = t_s;
    if repeat {
        t %= total;
    }
    let mut setpoint = Setpoint {
        force: points[points.len() - 1].force,
        rate_per_s: default_rate_per_s,
    };
    for w in points.windows(2) {
        if t < w[1].t_s {
            let slope = (w[1].force - w[0].force).abs() / (w[1].t_s - w[0].t_s);
            setpoint = Setpoint {
                force: w[1].force,
                rate_per_s: if slope > 0.0 {
                    slope
                } else {
                    default_rate_per_s
                },
            };
            break;
        }
    }
    setpoint
}

/// What happened while the profile advanced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ProfileEvent {
    /// A beat began.
    BeatStarted(Beat),
    /// A beat ended (at `end_ns`).
    BeatEnded(Beat),
}

impl ProfileRunner {
    /// Starts `spec` (already validated against `limits`) at `now_ns`.
    pub fn start(spec: ProfileSpec, limits: ReferenceLimits, now_ns: u64) -> Self {
        let cardiac = match &spec {
            ProfileSpec::Cardiac(c) => Some(CardiacRun {
                current: *c,
                pending: None,
                beat: Beat {
                    index: 0,
                    start_ns: now_ns + c.start_rest_ns(),
                    period_ns: c.period_ns(),
                    on_ns: c.on_ns(),
                    bpm: c.bpm,
                    target: c.amplitude,
                    amplitude: c.amplitude,
                },
                next_amplitude: c.amplitude,
            }),
            _ => None,
        };
        Self {
            spec,
            limits,
            start_ns: now_ns,
            cardiac,
        }
    }

    /// The profile as given.
    pub fn spec(&self) -> &ProfileSpec {
        &self.spec
    }

    /// The running beat of a cardiac profile.
    pub fn beat(&self) -> Option<Beat> {
        self.cardiac.map(|c| c.beat)
    }

    /// Parameters of the cardiac profile in force and, if any, those waiting for the next
    /// beat.
    pub fn cardiac(&self) -> Option<(CardiacSpec, Option<CardiacSpec>)> {
        self.cardiac.map(|c| (c.current, c.pending))
    }

    /// Replaces the parameters of a running cardiac profile from the next beat on (heart
    /// rate, duty, amplitude, edge rate). Returns false when no cardiac profile runs.
    pub fn retune_cardiac(&mut self, spec: CardiacSpec) -> bool {
        match &mut self.cardiac {
            Some(run) => {
                run.pending = Some(spec);
                run.next_amplitude = spec.amplitude;
                true
            }
            None => false,
        }
    }

    /// Sets the amplitude the next beat will use (the outer loop's output).
    pub fn set_next_amplitude(&mut self, amplitude: f64) {
        if let Some(run) = &mut self.cardiac {
            run.next_amplitude = amplitude;
        }
    }

    /// The operator's target amplitude of the beat to come (pending parameters included).
    pub fn next_target(&self) -> Option<f64> {
        self.cardiac
            .map(|c| c.pending.unwrap_or(c.current).amplitude)
    }

    /// Advances to `now_ns`, appending beat boundaries passed on the way to `events`, and
    /// returns the setpoint at `now_ns`.
    pub fn advance(&mut self, now_ns: u64, events: &mut Vec<ProfileEvent>) -> Setpoint {
        let t_s = now_ns.saturating_sub(self.start_ns) as f64 * 1e-9;
        let limits = self.limits;
        match &self.spec {
            ProfileSpec::Constant { force, rate_per_s } => Setpoint {
                force: *force,
                rate_per_s: rate_per_s.unwrap_or(limits.default_rate_per_s),
            },
            ProfileSpec::Steps {
                steps,
                repeat,
                rate_per_s,
            } => {
                let rate = rate_per_s.unwrap_or(limits.default_rate_per_s);
                steps_setpoint(steps, *repeat, rate, t_s)
            }
            ProfileSpec::Ramps { points, repeat } => {
                ramps_setpoint(points, *repeat, limits.default_rate_per_s, t_s)
            }
            ProfileSpec::Cardiac(_) => match self.cardiac.as_mut() {
                Some(run) => run.advance(now_ns, &limits, events),
                // A cardiac profile always has its run state; without one, rest.
                None => Setpoint {
                    force: 0.0,
                    rate_per_s: limits.max_rate_per_s,
                },
            },
        }
    }

    /// The setpoint changes scheduled after `now_ns`, in time order, into `out` (returns how
    /// many): for a cardiac profile the running contraction's end (in the rest before the
    /// first beat: its onset and end), then the onset and end
    /// of the next two beats (the next at the amplitude the outer loop has set for it, the
    /// one after at the same, its best guess). Other profiles announce nothing (an
    /// operator's setpoint, steps and ramps: rt-core decides causally). Call after
    /// [`Self::advance`] to `now_ns`.
    pub fn preview(&self, now_ns: u64, out: &mut [PreviewEdge]) -> usize {
        let Some(run) = &self.cardiac else {
            return 0;
        };
        let mut n = 0;
        let mut push = |t_ns: u64, force: f64, max_rate_per_s: f64| {
            if t_ns > now_ns && n < out.len() {
                out[n] = PreviewEdge {
                    t_ns,
                    force,
                    max_rate_per_s,
                };
                n += 1;
            }
        };
        let beat = run.beat;
        let rate = run.current.edge_rate(&self.limits);
        // In the rest before the first beat, its onset is the first edge.
        push(beat.start_ns, beat.amplitude, rate);
        push(beat.start_ns + beat.on_ns, 0.0, rate);
        let next = run.pending.unwrap_or(run.current);
        let next_rate = next.edge_rate(&self.limits);
        let (period, on) = (next.period_ns(), next.on_ns());
        for k in 0..2u64 {
            let start = beat.end_ns() + k * period;
            push(start, run.next_amplitude, next_rate);
            push(start + on, 0.0, next_rate);
        }
        n
    }

    /// The next time after `now_ns` at which the setpoint changes, if any (so the caller
    /// can publish edges on time instead of on its next period).
    pub fn next_change_ns(&self, now_ns: u64) -> Option<u64> {
        let t = now_ns.saturating_sub(self.start_ns);
        let after = |edges: &[f64], period: Option<f64>| -> Option<u64> {
            let t_s = t as f64 * 1e-9;
            let (base, local) = match period {
                Some(p) if p > 0.0 => ((t_s / p).floor() * p, t_s % p),
                _ => (0.0, t_s),
            };
            let edge = *edges.iter().find(|&&e| e > local + 1e-9)?;
            Some(self.start_ns + ((base + edge) * 1e9).ceil() as u64)
        };
        match &self.spec {
            ProfileSpec::Constant { .. } => None,
            ProfileSpec::Steps { steps, repeat, .. } => {
                let total: f64 = steps.iter().map(|s| s.hold_s).sum();
                let edges: Vec<f64> = steps
                    .iter()
                    .scan(0.0, |acc, s| {
                        *acc += s.hold_s;
                        Some(*acc)
                    })
                    .collect();
                after(&edges, repeat.then_some(total))
            }
            ProfileSpec::Ramps { points, repeat } => {
                let total = points[points.len() - 1].t_s;
                let edges: Vec<f64> = points.iter().map(|p| p.t_s).collect();
                after(&edges, repeat.then_some(total))
            }
            ProfileSpec::Cardiac(_) => {
                let run = self.cardiac?;
                if now_ns < run.beat.start_ns {
                    return Some(run.beat.start_ns);
                }
                let on_end = run.beat.start_ns + run.beat.on_ns;
                if now_ns < on_end {
                    return Some(on_end);
                }
                if now_ns < run.beat.end_ns() {
                    return Some(run.beat.end_ns());
                }
                // Not advanced yet past the running beat: the beats after it use the
                // pending parameters.
                let c = run.pending.unwrap_or(run.current);
                let (period, on) = (c.period_ns(), c.on_ns());
                let since = now_ns - run.beat.end_ns();
                let start = run.beat.end_ns() + since / period * period;
                Some(if now_ns < start + on {
                    start + on
                } else {
                    start + period
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn limits() -> ReferenceLimits {
        ReferenceLimits::default()
    }

    /// A cardiac profile whose first beat starts at once (no start rest).
    fn cardiac(bpm: f64, duty: f64, amplitude: f64) -> CardiacSpec {
        CardiacSpec {
            bpm,
            duty,
            amplitude,
            edge_rate_per_s: None,
            outer_loop: None,
            start_rest_ms: Some(0.0),
        }
    }

    /// By default the profile rests 200 ms before its first contraction, and the preview
    /// announces that contraction from the start (onset and end, then the next beat's), so
    /// rt-core's planner has the rest to plan it, as it has the rest phase before every
    /// later one. The beats keep their period from the first onset, and the next change is
    /// the onset. A rest outside [0, 2000] ms, or not a number, is refused.
    #[test]
    fn the_first_contraction_is_announced_through_the_start_rest() {
        let t0 = 5_000 * MS;
        let spec = CardiacSpec {
            start_rest_ms: None,
            ..cardiac(75.0, 0.4, 0.3)
        };
        assert_eq!(spec.start_rest_ns(), 200 * MS);
        let mut run = ProfileRunner::start(ProfileSpec::Cardiac(spec), limits(), t0);
        let mut ev = Vec::new();
        for k in [0, 100, 199] {
            assert_eq!(run.advance(t0 + k * MS, &mut ev).force, 0.0, "at {k} ms");
        }
        assert_eq!(run.next_change_ns(t0), Some(t0 + 200 * MS));
        let mut edges = [PreviewEdge::default(); 6];
        let n = run.preview(t0, &mut edges);
        let times: Vec<_> = edges[..n].iter().map(|e| (e.t_ns - t0) / MS).collect();
        assert_eq!(times, [200, 520, 1000, 1320, 1800, 2120]);
        assert_eq!(edges[0].force, 0.3);
        assert_eq!(run.advance(t0 + 200 * MS, &mut ev).force, 0.3);
        assert_eq!(run.advance(t0 + 519 * MS, &mut ev).force, 0.3);
        assert_eq!(run.advance(t0 + 520 * MS, &mut ev).force, 0.0);
        assert_eq!(run.advance(t0 + 1000 * MS, &mut ev).force, 0.3);
        let b = run.beat().unwrap();
        assert_eq!((b.index, b.start_ns), (1, t0 + 1000 * MS));
        for bad in [-1.0, 2000.5, f64::NAN] {
            let spec = CardiacSpec {
                start_rest_ms: Some(bad),
                ..spec
            };
            assert!(
                matches!(spec.validate(&limits()), Err(Rejection::Outside { .. })),
                "{bad}"
            );
        }
        CardiacSpec {
            start_rest_ms: Some(2000.0),
            ..spec
        }
        .validate(&limits())
        .unwrap();
    }

    /// The preview announces what the setpoints will do: inside a contraction its end,
    /// then the next two beats' onsets (at the amplitude the outer loop set for the next
    /// beat) and ends, each at the profile's edge rate; every announced edge is the
    /// setpoint change the runner then makes. Other profiles announce nothing.
    #[test]
    fn the_cardiac_preview_announces_the_edges_the_profile_then_makes() {
        let t0 = 5_000 * MS;
        let spec = ProfileSpec::Cardiac(cardiac(75.0, 0.4, 0.3));
        let mut run = ProfileRunner::start(spec, limits(), t0);
        let mut ev = Vec::new();
        let rate = limits().max_rate_per_s;
        run.advance(t0 + 10 * MS, &mut ev);
        run.set_next_amplitude(0.35);
        let mut edges = [PreviewEdge::default(); 6];
        let n = run.preview(t0 + 10 * MS, &mut edges);
        let at = |ms: u64, force: f64| PreviewEdge {
            t_ns: t0 + ms * MS,
            force,
            max_rate_per_s: rate,
        };
        assert_eq!(
            &edges[..n],
            &[
                at(320, 0.0),
                at(800, 0.35),
                at(1120, 0.0),
                at(1600, 0.35),
                at(1920, 0.0)
            ]
        );
        // In the rest: the running contraction's end is past.
        run.advance(t0 + 500 * MS, &mut ev);
        let n = run.preview(t0 + 500 * MS, &mut edges);
        assert_eq!(edges[0], at(800, 0.35));
        assert_eq!(n, 4);
        // Each announced edge is the setpoint the runner gives from then on.
        for e in &edges[..n] {
            let before = run.advance(e.t_ns - 1, &mut ev);
            assert_ne!(before.force, e.force, "{e:?}");
            let sp = run.advance(e.t_ns, &mut ev);
            assert_eq!((sp.force, sp.rate_per_s), (e.force, e.max_rate_per_s));
        }
        let constant = ProfileRunner::start(
            ProfileSpec::Constant {
                force: 0.3,
                rate_per_s: None,
            },
            limits(),
            t0,
        );
        assert_eq!(constant.preview(t0 + MS, &mut edges), 0);
    }

    /// 75 beats/min is an 800 ms beat; duty 0.4 contracts for 320 ms: the setpoint is the
    /// amplitude during [0, 320) ms of every beat and 0 after, and every boundary is
    /// reported once.
    #[test]
    fn cardiac_square_wave_timing() {
        let t0 = 5_000 * MS;
        let spec = ProfileSpec::Cardiac(cardiac(75.0, 0.4, 0.3));
        spec.validate(&limits()).unwrap();
        let mut run = ProfileRunner::start(spec, limits(), t0);
        let mut ev = Vec::new();
        for k in 0..(3 * 800) {
            let t = t0 + k * MS;
            let sp = run.advance(t, &mut ev);
            let in_beat = k % 800;
            let expect = if in_beat < 320 { 0.3 } else { 0.0 };
            assert_eq!(sp.force, expect, "at {k} ms");
            assert_eq!(sp.rate_per_s, 50.0);
        }
        let ends: Vec<_> = ev
            .iter()
            .filter_map(|e| match e {
                ProfileEvent::BeatEnded(b) => Some((b.index, b.start_ns - t0)),
                _ => None,
            })
            .collect();
        assert_eq!(ends, vec![(0, 0), (1, 800 * MS)]);
        assert_eq!(run.next_change_ns(t0 + 2400 * MS), Some(t0 + 2720 * MS));
        assert_eq!(run.next_change_ns(t0 + 2720 * MS), Some(t0 + 3200 * MS));
    }

    /// A heart-rate change takes effect at the next beat, not in the running one; the
    /// outer loop's amplitude is latched at the beat start.
    #[test]
    fn heart_rate_change_waits_for_the_next_beat() {
        let t0 = 1_000 * MS;
        let mut run =
            ProfileRunner::start(ProfileSpec::Cardiac(cardiac(60.0, 0.5, 0.4)), limits(), t0);
        let mut ev = Vec::new();
        run.advance(t0 + 100 * MS, &mut ev);
        assert!(run.retune_cardiac(cardiac(120.0, 0.5, 0.4)));
        run.set_next_amplitude(0.45);
        // Still the 1000 ms beat: on until 500 ms.
        assert_eq!(run.advance(t0 + 499 * MS, &mut ev).force, 0.4);
        assert_eq!(run.advance(t0 + 501 * MS, &mut ev).force, 0.0);
        assert_eq!(run.advance(t0 + 999 * MS, &mut ev).force, 0.0);
        // Next beat at 1000 ms: 500 ms period, on for 250 ms, amplitude 0.45.
        assert_eq!(run.advance(t0 + 1000 * MS, &mut ev).force, 0.45);
        assert_eq!(run.advance(t0 + 1249 * MS, &mut ev).force, 0.45);
        assert_eq!(run.advance(t0 + 1251 * MS, &mut ev).force, 0.0);
        assert_eq!(run.advance(t0 + 1500 * MS, &mut ev).force, 0.45);
        let b = run.beat().unwrap();
        assert_eq!((b.index, b.period_ns, b.bpm), (2, 500 * MS, 120.0));
    }

    #[test]
    fn steps_and_ramps_follow_their_definition() {
        let t0 = 0;
        let steps = ProfileSpec::Steps {
            steps: vec![
                Step {
                    force: 0.2,
                    hold_s: 1.0,
                },
                Step {
                    force: 0.5,
                    hold_s: 0.5,
                },
            ],
            repeat: true,
            rate_per_s: Some(2.0),
        };
        steps.validate(&limits()).unwrap();
        let mut r = ProfileRunner::start(steps, limits(), t0);
        let mut ev = Vec::new();
        assert_eq!(r.advance(999 * MS, &mut ev).force, 0.2);
        assert_eq!(r.advance(1000 * MS, &mut ev).force, 0.5);
        assert_eq!(r.advance(1600 * MS, &mut ev).force, 0.2);
        assert_eq!(r.advance(1600 * MS, &mut ev).rate_per_s, 2.0);
        assert_eq!(r.next_change_ns(1600 * MS), Some(2500 * MS));

        let ramps = ProfileSpec::Ramps {
            points: vec![
                RampPoint {
                    t_s: 0.0,
                    force: 0.0,
                },
                RampPoint {
                    t_s: 2.0,
                    force: 0.5,
                },
                RampPoint {
                    t_s: 3.0,
                    force: 0.5,
                },
            ],
            repeat: false,
        };
        ramps.validate(&limits()).unwrap();
        let mut r = ProfileRunner::start(ramps, limits(), t0);
        let sp = r.advance(500 * MS, &mut ev);
        assert_eq!(sp.force, 0.5);
        assert!((sp.rate_per_s - 0.25).abs() < 1e-12);
        assert_eq!(r.advance(2500 * MS, &mut ev).force, 0.5);
        assert_eq!(r.advance(9000 * MS, &mut ev).force, 0.5);
        assert_eq!(r.next_change_ns(500 * MS), Some(2000 * MS));
        assert_eq!(r.next_change_ns(9000 * MS), None);
    }

    #[test]
    fn invalid_profiles_say_why() {
        let l = limits();
        let e = ProfileSpec::Cardiac(cardiac(250.0, 0.4, 0.3))
            .validate(&l)
            .unwrap_err();
        assert!(
            matches!(&e, Rejection::Outside { what, value, .. } if what == "heart rate" && *value == 250.0),
            "{e}"
        );
        let e = ProfileSpec::Cardiac(cardiac(75.0, 0.4, f64::NAN))
            .validate(&l)
            .unwrap_err();
        assert!(e.to_string().contains("amplitude is NaN"), "{e}");
        let slow_edges = CardiacSpec {
            edge_rate_per_s: Some(1.0),
            ..cardiac(75.0, 0.4, 0.5)
        };
        let e = ProfileSpec::Cardiac(slow_edges).validate(&l).unwrap_err();
        assert!(
            matches!(e, Rejection::EdgeTooLong { edge_ms, .. } if (edge_ms - 500.0).abs() < 1e-9),
            "{e}"
        );
        let steep = ProfileSpec::Ramps {
            points: vec![
                RampPoint {
                    t_s: 0.0,
                    force: 0.0,
                },
                RampPoint {
                    t_s: 0.01,
                    force: 1.0,
                },
            ],
            repeat: false,
        };
        let e = steep.validate(&l).unwrap_err();
        assert!(matches!(e, Rejection::TooFast { .. }), "{e}");
        assert!(e.to_string().contains("slope 100"), "{e}");
        let e = ProfileSpec::Steps {
            steps: vec![],
            repeat: false,
            rate_per_s: None,
        }
        .validate(&l)
        .unwrap_err();
        assert!(
            matches!(&e, Rejection::Outside { what, value, .. } if what == "number of steps" && *value == 0.0),
            "{e}"
        );
    }
}
