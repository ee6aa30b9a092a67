//! The interface every simulated muscle implements, so the data-set recorder, the CLI and
//! the virtual stimulator on the CAN bus can drive any of them (the Ding model, an LMN model
//! file) the same way.

/// One stimulation pulse as delivered by the stimulator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pulse {
    /// Pulse amplitude in milliamperes.
    pub amplitude_ma: f64,
    /// Pulse (phase) width in microseconds.
    pub width_us: f64,
}

impl Pulse {
    /// The thesis protocol's supramaximal pulse (5.1): 200 us; the amplitude is nominal.
    pub const SUPRAMAXIMAL: Pulse = Pulse {
        amplitude_ma: 20.0,
        width_us: 200.0,
    };
}

/// A muscle advanced in fixed steps of [`MusclePlant::ts`] seconds.
///
/// Timing convention (shared with the data-set format): sample k covers
/// `[k Ts, (k+1) Ts)`. A pulse passed to `step` fires at `t = k Ts`; `step` advances the
/// muscle to `t = (k+1) Ts` and returns the force there, in newtons. A muscle at rest has
/// zero force, so a record's first sample is the force at `t = 0` before any step.
pub trait MusclePlant: Send {
    /// Sample period in seconds.
    fn ts(&self) -> f64;
    /// Advances one sample, firing `pulse` at its start; returns the force (N) at its end.
    fn step(&mut self, pulse: Option<Pulse>) -> f64;
    /// Returns the muscle to rest (no force, no stimulation history).
    fn reset(&mut self);
    /// The value of a record's first sample (`t = 0`, before any `step`). A muscle at rest
    /// has zero force; a force sensor adds its offset and noise.
    fn initial_force(&mut self) -> f64 {
        0.0
    }
    /// Lets `seconds` pass without stimulation (the thesis rests 30 s between records).
    /// Without slow state (fatigue) this is a [`MusclePlant::reset`]; a fatiguing muscle
    /// recovers only partially.
    fn rest(&mut self, seconds: f64) {
        let _ = seconds;
        self.reset();
    }
}

/// A boxed plant is a plant, so tools can choose the muscle at run time.
impl<P: MusclePlant + ?Sized> MusclePlant for Box<P> {
    fn ts(&self) -> f64 {
        (**self).ts()
    }
    fn step(&mut self, pulse: Option<Pulse>) -> f64 {
        (**self).step(pulse)
    }
    fn reset(&mut self) {
        (**self).reset()
    }
    fn initial_force(&mut self) -> f64 {
        (**self).initial_force()
    }
    fn rest(&mut self, seconds: f64) {
        (**self).rest(seconds)
    }
}

/// A muscle plant under an emulated device (`fes_virtual_stimulator`): the device's pulse,
/// in the same physical units, becomes the muscle's. The emulators drive their own narrow
/// plant trait so that they need no muscle model; this is the one adapter, used by
/// `sim-muscle stimulator`, `sim-muscle rehastim2` and `test-stimulator`.
pub struct OnDevice<P>(pub P);

impl<P: MusclePlant> fes_virtual_stimulator::Plant for OnDevice<P> {
    fn ts(&self) -> f64 {
        self.0.ts()
    }

    fn step(&mut self, pulse: Option<fes_virtual_stimulator::plant::Pulse>) -> f64 {
        self.0.step(pulse.map(|p| Pulse {
            amplitude_ma: p.amplitude_ma,
            width_us: p.width_us,
        }))
    }
}
